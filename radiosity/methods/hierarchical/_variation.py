"""What a link's factor does across its receiver, pushed onto the leaves below it.

A link (r <- s) keeps the mean of ``F V`` over r's 3 x 3 Gauss points (its factor) and each
point's deviation from that mean (``Links.shape``). Pushing the mean alone gives every leaf
below r the same value, and where the links of a leaf's ancestors all lean one way their small
errors add up: in an empty 6 x 5 x 3 m furnace room at ``draft`` an interior wall leaf gathered
0.960 of its row (its level-3 ancestor's 30 links 0.309 where the leaf's own factors to the
same sources sum to 0.334) and a leaf at the floor 1.046, so B was off by -2.0% and +2.4%.

Here the deviations of every link with receiver r, weighted by its source's radiosity, are
gathered per point (9 numbers per receiver), fitted by a quadratic in r's plane (weighted least
squares with zero mean over r's points, so the link's total over r is unchanged), and each leaf
below r takes the fit's mean over its own Gauss points. The same room's rows then sum to 1
within 2e-4. The fit and the leaf means depend on the geometry only: they are folded into one
sparse matrix from the gathered points to the leaves (9 entries per leaf and ancestor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...formfactors import patch_points
from ._elements import Elements
from ._links_kernel import collect_deviations, gather_deviations

CHUNK_PAIRS = 1 << 16  # receivers, or (leaf, ancestor) pairs, per numpy batch: 9 x 5 floats each


@dataclass
class Variation:
    """G's part that gathers the links' point deviations onto their receivers' 9 Gauss
    points (rows ``9 q + i`` of its output for receiver ``q``), link by link from their int8
    codes: 17 bytes a link (column, codes, scale; the receivers as CSR row pointers)."""

    indptr: np.ndarray  # (m + 1,) int64: the links of receiver q are indptr[q]:indptr[q + 1]
    column: np.ndarray  # (n,) int32: the source element
    codes: np.ndarray  # (n, 9) int8: ``Links.shape``
    scale: np.ndarray  # (n,) float32: ``Links.shape_scale / 127``

    @property
    def n_out(self) -> int:
        return 9 * (len(self.indptr) - 1)

    @property
    def nbytes(self) -> int:
        return self.indptr.nbytes + self.column.nbytes + self.codes.nbytes + self.scale.nbytes

    def gathered(self, x: np.ndarray) -> np.ndarray:
        """(9 m,) each receiver's deviations at its points, summed over its links times x[s]."""
        out = np.zeros((len(self.indptr) - 1, self.codes.shape[1]))
        gather_deviations(self.indptr, self.column, self.codes, self.scale, x, out)
        return out.ravel()

    def add_collected(self, y: np.ndarray, x: np.ndarray) -> None:
        """x += (this part of G).T @ y, y of length ``n_out``."""
        collect_deviations(self.indptr, self.column, self.codes, self.scale,
                           np.ascontiguousarray(y).reshape(-1, self.codes.shape[1]), x)


def variation_part(el: Elements, r: np.ndarray, s: np.ndarray, codes: np.ndarray, scale: np.ndarray,
                   leaves: np.ndarray) -> tuple[Variation, sp.csr_matrix] | None:
    """(G's part, P's columns) of the links (r <- s) whose receiver has leaves below it and
    whose points deviate from their mean (``scale > 0``); None where no link does."""
    keep = np.flatnonzero((el.first_child[r] >= 0) & (scale > 0))
    if not len(keep):
        return None
    order = keep[np.argsort(r[keep], kind="stable")]
    receivers, count = np.unique(r[order], return_counts=True)
    indptr = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    part = Variation(indptr, s[order].astype(np.int32), np.ascontiguousarray(codes[order]),
                     (scale[order] / np.float32(127.0)).astype(np.float32))
    return part, variation_push(el, receivers, leaves)


def variation_push(el: Elements, receivers: np.ndarray, leaves: np.ndarray) -> sp.csr_matrix:
    """(n_leaves, 9 m) sparse: leaf l's mean of the quadratic that fits receiver q's gathered
    point deviations, for each ancestor q of l among ``receivers`` (sorted).

    Receivers go in chunks of ``CHUNK_PAIRS`` with the (leaf, ancestor) pairs below them: the
    fits of every receiver at once took 0.5 kB each (a million-face scene has about as many
    receivers)."""
    rows, elements = el.ancestry(leaves)
    q = np.minimum(np.searchsorted(receivers, elements), len(receivers) - 1)
    hit = np.flatnonzero(receivers[q] == elements)
    order = hit[np.argsort(q[hit], kind="stable")]
    rows, q = rows[order], q[order]
    values = np.empty((len(rows), 9))
    for a in range(0, len(receivers), CHUNK_PAIRS):
        fit, centre, axes, mean, _ = _quadratic_fits(el, receivers[a:a + CHUNK_PAIRS])
        first, last = np.searchsorted(q, [a, a + CHUNK_PAIRS])
        for b in range(first, last, CHUNK_PAIRS):
            pair = slice(b, min(b + CHUNK_PAIRS, last))
            at = q[pair] - a
            points, weights = patch_points(el.quads[leaves[rows[pair]]], 3)
            weights = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-300)
            basis = _basis(points, centre[at], axes[at]) - mean[at][:, None, :]  # (p, 9 points, 5)
            values[pair] = np.einsum("pk,pki->pi", np.einsum("pi,pik->pk", weights, basis), fit[at])
    columns = 9 * q[:, None] + np.arange(9)
    return sp.csr_matrix((values.ravel(), (np.repeat(rows, 9), columns.ravel())),
                         shape=(len(leaves), 9 * len(receivers)))


def fit_residuals(el: Elements, receivers: np.ndarray, deviations: np.ndarray) -> np.ndarray:
    """(m, 9) what the quadratic fit of each receiver's point ``deviations`` (m, 9) leaves out
    at its points: the error the push makes there."""
    out = np.empty_like(deviations)
    for a in range(0, len(receivers), CHUNK_PAIRS):
        fit, _, _, _, basis = _quadratic_fits(el, receivers[a:a + CHUNK_PAIRS])
        d = deviations[a:a + CHUNK_PAIRS]
        out[a:a + CHUNK_PAIRS] = d - np.einsum("mik,mk->mi", basis, np.einsum("mkj,mj->mk", fit, d))
    return out


def _quadratic_fits(el: Elements, receivers: np.ndarray):
    """Per receiver: the (5, 9) map from deviations at its Gauss points to the coefficients of
    the zero-mean quadratic (xi, eta, xi^2, xi eta, eta^2) fitting them by weighted least
    squares, the frame (centre, in-plane axes over the element's size, the basis' mean), and
    the zero-mean basis at its own points (9, 5)."""
    quads, normal = el.quads[receivers], el.normal[receivers]
    centre = el.centroid[receivers]
    edge = quads[:, 1] - quads[:, 0]
    edge -= normal * np.einsum("mc,mc->m", edge, normal)[:, None]
    t1 = edge / np.maximum(np.linalg.norm(edge, axis=1, keepdims=True), 1e-300)
    t2 = np.cross(normal, t1)
    size = np.sqrt(np.maximum(el.area[receivers], 1e-300))[:, None]
    axes = np.stack([t1 / size, t2 / size], axis=1)  # (m, 2, 3)
    points, weights = patch_points(quads, 3)
    weights = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-300)
    basis = _basis(points, centre, axes)
    mean = np.einsum("mi,mik->mk", weights, basis)
    basis -= mean[:, None, :]
    normal_matrix = np.einsum("mik,mi,mil->mkl", basis, weights, basis)
    # pinv: a sliver's points lie near a line, and its quadratic across it is not determined
    fit = np.einsum("mkl,mil,mi->mki", np.linalg.pinv(normal_matrix, rcond=1e-10, hermitian=True), basis, weights)
    return fit, centre, axes, mean, basis


def _basis(points: np.ndarray, centre: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(m, p, 5): xi, eta, xi^2, xi eta, eta^2 of points (m, p, 3) in the frames (centre (m, 3),
    axes (m, 2, 3))."""
    local = np.einsum("mpc,mac->mpa", points - centre[:, None, :], axes)
    xi, eta = local[..., 0], local[..., 1]
    return np.stack([xi, eta, xi * xi, xi * eta, eta * eta], axis=-1)
