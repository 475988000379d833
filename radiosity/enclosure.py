"""View-factor matrix diagnostics (closure, reciprocity) and their enforcement.

Thermal engineers expect two identities from a view-factor matrix: reciprocity
``A_i F_ij = A_j F_ji`` and, in a closed enclosure, closure ``sum_j F_ij = 1``. A computed F
meets both only to its quadrature and visibility error. We enforce them the way thermal codes
do: symmetrise the exchange areas ``G = A F`` (reciprocity), then, for closure, scale G
symmetrically, ``G' = D G D``, until every row of G' sums to its area (a symmetric
Sinkhorn-Knopp iteration). Rows are never renormalised one by one: that would break
reciprocity and hide where the error was.
"""

from __future__ import annotations

from dataclasses import dataclass

import warnings

import numpy as np
import scipy.sparse as sp

from ._errors import RadiosityError, RadiosityWarning

__all__ = ["Diagnostics", "diagnose", "enforce_reciprocity", "check_closed", "NotClosedError", "CLOSURE_SLACK"]

# Closure is refused where a row misses 1 by more than this many times the fill's requested
# tolerance (formfactor_rtol + visibility_atol): a row sums about n_j entries, each within its
# tolerance, and the errors of a closed room's rows stay well below 10 x that sum in practice.
CLOSURE_SLACK = 10.0


class NotClosedError(RadiosityError, ValueError):
    """Closure was asked for, but the rows show the scene is not a closed enclosure."""


@dataclass(frozen=True)
class Diagnostics:
    """Closure and reciprocity of a view-factor matrix.

    Attributes
    ----------
    row_sums : (n,) float
        sum_j F_ij; 1 in a closed enclosure.
    closure_error : float
        max_i |1 - sum_j F_ij| (meaningful for enclosures only).
    reciprocity_error : float
        max_ij |A_i F_ij - A_j F_ji| / max(A_i F_ij): the relative asymmetry of exchange areas.
    """

    row_sums: np.ndarray
    closure_error: float
    reciprocity_error: float


def diagnose(F: sp.spmatrix, area: np.ndarray) -> Diagnostics:
    """Closure and reciprocity of ``F`` (rows are receivers of the fill, F[i, j] = F(i -> j)).

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> F = sp.csr_matrix(np.array([[0.0, 1.0], [0.5, 0.5]]))
    >>> d = diagnose(F, np.array([1.0, 2.0]))
    >>> float(d.reciprocity_error), float(d.closure_error)
    (0.0, 0.0)
    """
    F = sp.csr_matrix(F)
    rows = np.asarray(F.sum(axis=1)).ravel()
    G = sp.diags(area) @ F
    asym = abs(G - G.T)
    scale = abs(G).max() if G.nnz else 1.0
    recip = float(asym.max() / scale) if asym.nnz and scale > 0 else 0.0
    return Diagnostics(rows, float(np.abs(1 - rows).max()) if len(rows) else 0.0, recip)


def enforce_reciprocity(F: sp.spmatrix, area: np.ndarray, *, closure: bool = False, rtol: float = 1e-13,
                        maxiter: int = 1000) -> sp.csr_matrix:
    """F with exact reciprocity (and, if ``closure``, rows summing to 1), changed as little as possible.

    Parameters
    ----------
    F : (n, n) sparse
        View-factor matrix, F[i, j] = F(i -> j).
    area : (n,) float
        Patch areas.
    closure : bool, default: False
        Also scale the exchange areas symmetrically so every row sums to 1. Only meaningful
        for a closed enclosure (every patch sees only other patches); an open scene's rows
        legitimately sum to less than 1.
    rtol : float, default: 1e-13
        Closure tolerance of the symmetric scaling.

    Returns
    -------
    scipy.sparse.csr_matrix

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> F = sp.csr_matrix(np.array([[0.0, 1.01], [0.49, 0.5]]))
    >>> Fe = enforce_reciprocity(F, np.array([1.0, 2.0]), closure=True)
    >>> np.round(Fe.toarray(), 6).tolist()
    [[0.0, 1.0], [0.5, 0.5]]
    """
    F = sp.csr_matrix(F, dtype=float)
    G = sp.diags(area) @ F
    G = ((G + G.T) * 0.5).tocsr()
    if closure:
        d = np.ones(len(area))
        for _ in range(maxiter):
            row = d * (G @ d)
            if np.all(np.abs(row - area) <= rtol * area):
                break
            d = d * np.sqrt(area / np.where(row > 0, row, area))
        else:
            worst = float(np.abs(row / area - 1).max())
            warnings.warn(f"closure could not be enforced (worst row off by {worst:.2g} after {maxiter} "
                          "scalings): the scene is probably not a closed enclosure", RadiosityWarning, stacklevel=2)
        G = (sp.diags(d) @ G @ sp.diags(d)).tocsr()
    return (sp.diags(1.0 / area) @ G).tocsr()


def check_closed(F: sp.spmatrix, active: np.ndarray, rtol: float, *, names=None, patch_object=None) -> float:
    """Raise unless every active row of F sums to 1 within ``CLOSURE_SLACK * rtol``.

    Parameters
    ----------
    F : (n, n) sparse
    active : (n,) bool
        Rows to check (obstructions and hidden patches have none).
    rtol : float
        The fill's tolerance (``formfactor_rtol + visibility_atol``).

    Returns
    -------
    float
        The worst ``|1 - sum_j F_ij|``.

    Raises
    ------
    NotClosedError
        Rows fall short of (or exceed) 1 by more than the tolerance; the message gives the
        worst row, its deficit and the tolerance.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> check_closed(sp.csr_matrix(np.array([[0, 1.0], [1.0, 0]])), np.ones(2, bool), 1e-6)
    0.0
    """
    rows = np.asarray(sp.csr_matrix(F).sum(axis=1)).ravel()
    off = np.where(active, 1.0 - rows, 0.0)
    if not len(off):
        return 0.0
    worst = int(np.argmax(np.abs(off)))
    tolerance = CLOSURE_SLACK * rtol
    if abs(off[worst]) <= tolerance:
        return float(abs(off[worst]))
    what = f"patch {worst}"
    if names is not None and patch_object is not None:
        what += f" (object {names[patch_object[worst]]!r})"
    kind = "deficit" if off[worst] > 0 else "surplus"
    short, over = int((off > tolerance).sum()), int((off < -tolerance).sum())
    msg = (f"closure refused: {what} sums to {rows[worst]:.6g} (worst row {kind} {abs(off[worst]):.3g}, "
           f"allowed {tolerance:.1g}); {short} row(s) short, {over} over 1: not a closed enclosure, or the "
           "fill lost light; --force (force=True) scales anyway")
    raise NotClosedError(msg)
