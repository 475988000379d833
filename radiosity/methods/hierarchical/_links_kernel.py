"""numba kernels of the element links that gather from their source's children (see
:class:`._hierarchy._Children`): G's part for them, applied link by link from each link's value
and its four shares instead of four entries of a sparse matrix each."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def gather_children(r, first, value, shares, x, y):
    """y[r[k]] += value[k] * sum_c shares[k, c] * x[first[k] + c] for every link k (serial:
    links of one receiver add into the same entry)."""
    for k in range(len(r)):
        f = first[k]
        y[r[k]] += value[k] * (shares[k, 0] * x[f] + shares[k, 1] * x[f + 1]
                               + shares[k, 2] * x[f + 2] + shares[k, 3] * x[f + 3])


@njit(cache=True)
def collect_children(r, first, value, shares, y, x):
    """x[first[k] + c] += value[k] * shares[k, c] * y[r[k]] for every link k and child c
    (the transpose of :func:`gather_children`)."""
    for k in range(len(r)):
        taken = value[k] * y[r[k]]
        f = first[k]
        for c in range(4):
            x[f + c] += taken * shares[k, c]
