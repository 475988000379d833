"""The radiosity system (I - rho F) B = E per RGB channel, its solvers and energy balance."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..._errors import RadiosityError, RadiosityWarning

__all__ = ["SolverReport", "solve_system", "energy_balance", "gaining_patches", "gained_power", "bound_rows",
           "SOLVERS"]

SOLVERS = ("auto", "direct", "bicgstab", "gmres", "jacobi", "gauss-seidel", "progressive")

# Below this many unknowns a sparse LU is cheaper than setting up a Krylov solve.
DIRECT_MAX = 1500

# An iterative solve is accepted when its relative residual is within this factor of ``rtol``
# (progressive refinement stops on unshot power, which bounds the residual only up to the
# reflectances), and never above ACCEPT_MAX: a result worse than that is not called a solution.
ACCEPT_FACTOR = 100.0
ACCEPT_MAX = 1e-6


@dataclass
class SolverReport:
    """What the solver did, per RGB channel.

    ``method`` is the solver asked for (``auto`` resolved); ``fallback`` names, per channel, the
    solver that produced the answer when the first one stopped at its cap without converging
    (``None`` where it converged).
    """

    method: str
    iterations: list[int]
    residual: list[float]  # ||(I - rho F) B - E|| / ||E|| per channel
    fallback: list[str | None] = field(default_factory=list)


def _operator(F: sp.csr_matrix, rho: np.ndarray) -> sp.csr_matrix:
    return (sp.identity(F.shape[0], format="csr") - sp.diags(rho) @ F).tocsr()


def _relative_residual(A, b, x) -> float:
    norm = np.linalg.norm(b)
    return float(np.linalg.norm(A @ x - b) / norm) if norm > 0 else float(np.linalg.norm(A @ x))


def _stationary(F, rho, e, rtol, gauss_seidel: bool, maxiter: int = 10_000):
    """Jacobi (B <- E + rho F B) or Gauss-Seidel sweeps; converge since rho F has norm < 1."""
    b = e.copy()
    A = _operator(F, rho)
    if gauss_seidel:
        lower = sp.tril(A, format="csr")
        upper = (A - lower).tocsr()
    for it in range(1, maxiter + 1):
        if gauss_seidel:
            b = spla.spsolve_triangular(lower, e - upper @ b, lower=True)
        else:
            b = e + rho * (F @ b)
        if _relative_residual(A, e, b) <= rtol:
            return b, it
    return b, maxiter


def progressive(F: sp.csr_matrix, area: np.ndarray, rho: np.ndarray, e: np.ndarray, rtol: float,
                maxiter: int | None = None, callback=None):
    """Progressive refinement (Cohen et al. 1988): shoot the largest unshot power first.

    Stops when the unshot power is below ``rtol`` of the emitted power. ``callback(b, it)`` is
    called every few shots with the current estimate, so callers can show intermediate results.
    """
    n = len(e)
    Ft = F.T.tocsr()  # column j of F, as a row: F[i, j] for all receivers i
    b = e.copy()
    unshot = e.copy()
    emitted = float((area * e).sum())
    maxiter = maxiter or 50 * n
    for it in range(1, maxiter + 1):
        power = area * unshot
        j = int(np.argmax(power))
        if power[j] <= rtol * max(emitted, 1e-300):
            return b, it - 1
        start, stop = Ft.indptr[j], Ft.indptr[j + 1]
        receivers = Ft.indices[start:stop]
        # Radiosity reaching i from j: B_j F_ji A_j / A_i = B_j F_ij (reciprocity).
        gain = rho[receivers] * unshot[j] * Ft.data[start:stop]
        b[receivers] += gain
        unshot[receivers] += gain
        unshot[j] = 0.0
        if callback is not None and it % max(1, n // 10) == 0:
            callback(b, it)
    return b, maxiter


def accepted_residual(rtol: float) -> float:
    """The largest relative residual a solve with tolerance ``rtol`` may end with."""
    return min(max(ACCEPT_FACTOR * rtol, 1e-12), ACCEPT_MAX)


def _direct(A: sp.csr_matrix, e: np.ndarray) -> np.ndarray:
    return spla.spsolve(A.tocsc(), e)


def _first_attempt(method, F, r, e, area, A, rtol):
    """The asked-for solver's answer and iteration count (it may have stopped at its cap)."""
    if method == "direct":
        return _direct(A, e), 1
    if method in ("bicgstab", "gmres"):
        counter = [0]

        def count(_):
            counter[0] += 1

        fn = spla.bicgstab if method == "bicgstab" else spla.gmres
        kwargs = {"callback_type": "pr_norm"} if method == "gmres" else {}
        x, _info = fn(A, e, x0=e.copy(), rtol=rtol, atol=0.0, maxiter=1000, callback=count, **kwargs)
        return x, counter[0]
    if method in ("jacobi", "gauss-seidel"):
        return _stationary(F, r, e, rtol, method == "gauss-seidel")
    return progressive(F, area, r, e, rtol)


def _fall_back(method, F, r, e, area, A, rtol) -> tuple[np.ndarray, str, float]:
    """Answer with the first solver that converges, after ``method`` stopped at its cap.

    Krylov solvers come first (no fill-in); a direct LU last, after the memory check. A system
    no solver can bring to the accepted residual is refused rather than returned.
    """
    residual = np.inf
    for other in ("gmres", "direct"):
        if other == method:
            continue
        if other == "direct":
            from ... import _memory

            _memory.check_solve(A.shape[0], A.nnz, "direct")
        x, _ = _first_attempt(other, F, r, e, area, A, rtol)
        residual = _relative_residual(A, e, x)
        if residual <= accepted_residual(rtol):
            return x, other, residual
    raise RadiosityError(f"the radiosity system did not converge with {method}, gmres or a direct solve "
                         f"(best residual {residual:.1e}); are reflectances near 1 in a closed scene?")


def solve_system(F: sp.csr_matrix, rho: np.ndarray, emission: np.ndarray, area: np.ndarray, *,
                 method: str = "auto", rtol: float = 1e-10) -> tuple[np.ndarray, SolverReport]:
    """Solve (I - rho F) B = E for each channel of ``emission`` (n, 3)."""
    if method not in SOLVERS:
        raise TypeError(f"unknown solver {method!r}; valid: {', '.join(SOLVERS)}")
    n = F.shape[0]
    if method == "auto":
        method = "direct" if n <= DIRECT_MAX else "bicgstab"
    out = np.zeros_like(emission)
    report = SolverReport(method, [], [])
    for c in range(emission.shape[1]):
        e, r = emission[:, c], rho[:, c]
        A = _operator(F, r)
        if not e.any():
            report.iterations.append(0)
            report.residual.append(0.0)
            report.fallback.append(None)
            continue
        x, it = _first_attempt(method, F, r, e, area, A, rtol)
        residual = _relative_residual(A, e, x)
        fallback = None
        if not residual <= accepted_residual(rtol):
            x, fallback, residual = _fall_back(method, F, r, e, area, A, rtol)
            warnings.warn(f"{method} stopped after {it:,} iterations without converging; channel {c} "
                          f"was solved with {fallback} instead (residual {residual:.1e})",
                          RadiosityWarning, stacklevel=2)
        out[:, c] = x
        report.iterations.append(int(it))
        report.residual.append(residual)
        report.fallback.append(fallback)
    return np.clip(out, 0.0, None), report


def energy_balance(F: sp.csr_matrix, area: np.ndarray, rho: np.ndarray, emission: np.ndarray,
                   radiosity: np.ndarray) -> dict[str, list[float]]:
    """Emitted, absorbed and escaped power per channel (W); emitted = absorbed + escaped.

    ``escaped`` counts power leaving the patches that reaches no patch's front (it leaves
    through an opening or lands on a back face), from the columns of F: sum_i A_i F_ij is the
    part of patch j's power that lands on fronts. ``emitted - absorbed - escaped`` is zero up
    to the solver's residual, so it checks the solve, not the fill.
    """
    irradiance = F @ radiosity
    emitted = (area[:, None] * emission).sum(axis=0)
    absorbed = (area[:, None] * (1 - rho) * irradiance).sum(axis=0)
    reached = F.T @ area  # sum_i A_i F_ij = power fraction from j landing on some front, times A_j
    escaped = ((area - reached)[:, None] * radiosity).sum(axis=0)
    return {"emitted": emitted.tolist(), "absorbed": absorbed.tolist(), "escaped": escaped.tolist()}


# "escaped" below -ESCAPED_ROUND_OFF x emitted is not round-off: some rows of F sum above 1.
ESCAPED_ROUND_OFF = 1e-9


def front_share(F: sp.csr_matrix, area: np.ndarray) -> np.ndarray:
    """(n,) share of each patch's power that lands on some front, ``sum_i A_i F_ij / A_j`` (its
    row sum where reciprocity holds); 1 for patches without area."""
    area = np.asarray(area, float)
    return np.where(area > 0, (F.T @ area) / np.where(area > 0, area, 1.0), 1.0)


def gaining_patches(F: sp.csr_matrix, area: np.ndarray, radiosity: np.ndarray, patch_object: np.ndarray,
                    names: list[str], *, tol: float = ESCAPED_ROUND_OFF, limit: int = 10) -> list[dict]:
    """The patches whose light is more than all accounted for: what makes "escaped" negative.

    ``sum_i A_i F_ij / A_j`` is the share of patch j's power that lands on some front (the row
    sum of j where reciprocity holds); above 1 the fill created light. Patches whose share
    exceeds 1 by more than ``tol`` are listed, the largest gain of power first.

    Returns
    -------
    list of dict
        Up to ``limit`` entries ``{"object", "patch", "share", "gain_W"}``: the object's name,
        the patch index, the share (> 1) and the power gained per channel, (share - 1) A_j B_j.
    """
    area = np.asarray(area, float)
    share = front_share(F, area)
    excess = share - 1.0
    gain = (excess * area)[:, None] * np.asarray(radiosity, float).reshape(len(area), -1)
    idx = np.flatnonzero(excess > tol)
    idx = idx[np.argsort(-gain[idx].sum(axis=1), kind="stable")][:limit]
    return [{"object": names[int(patch_object[k])], "patch": int(k), "share": float(share[k]),
             "gain_W": [float(g) for g in gain[k]]} for k in idx]


def gain_note(energy: dict[str, list[float]], gaining: list[dict], tol: float = ESCAPED_ROUND_OFF, *,
              gained: np.ndarray | None = None) -> str | None:
    """A note naming the patches that gain, when the light they gain exceeds ``tol``; else None.

    :func:`radiosity.solve` passes the fill's own tolerance (``formfactor_rtol +
    visibility_atol``): a closed cube at draft has rows 1 + 2.9e-7, which is the quadrature's
    error, not news. Without ``gained`` the test is "escaped" below ``-tol`` x emitted. With
    ``gained`` ((3,) W: the power the filled F's rows above 1 would create, before
    :func:`bound_rows` scaled them to 1) it is ``gained`` above ``tol`` x emitted, and the note
    says the rows were scaled.
    """
    tol = max(tol, ESCAPED_ROUND_OFF)
    emitted = np.abs(np.asarray(energy["emitted"], float))
    if gained is None:
        over = (np.asarray(energy["escaped"], float) < -tol * emitted).any()
    else:
        over = (np.asarray(gained, float) > tol * emitted).any()
    if not gaining or not over:
        return None
    worst = ", ".join(f"{g['object']} patch {g['patch']} (row sum 1{g['share'] - 1:+.1e})" for g in gaining[:5])
    advice = "a finer preset or tighter formfactor_rtol / visibility_atol reduces it"
    if gained is not None:
        share = float((np.asarray(gained, float) / np.where(emitted > 0, emitted, 1.0)).max())
        return (f"energy balance: rows of F summed above 1 ({share:.2e} of the emitted power would be created), "
                f"most at {worst}; they were scaled down to 1, with their partners' entries (reciprocity kept), "
                f"so that no light is created; {advice}")
    share = float((-np.asarray(energy["escaped"], float) / np.where(emitted > 0, emitted, 1.0)).max())
    return (f"energy balance: 'escaped' is negative ({share:.2e} of the emitted power): rows of F sum above 1, "
            f"most at {worst}; {advice}")


def gained_power(F: sp.csr_matrix, area: np.ndarray, radiosity: np.ndarray) -> np.ndarray:
    """(3,) W: the light that the rows of ``F`` above 1 create, sum_j max(share_j - 1, 0) A_j B_j."""
    area = np.asarray(area, float)
    excess = np.maximum(front_share(F, area) - 1.0, 0.0)
    return (excess * area) @ np.asarray(radiosity, float).reshape(len(area), -1)


def bound_rows(F: sp.csr_matrix, area: np.ndarray, tol: float = ESCAPED_ROUND_OFF) -> tuple[sp.csr_matrix, int]:
    """F with no row above 1 and reciprocity kept: entries scaled by ``min(s_i, s_j)``.

    A row of F above 1 creates light: in a closed room the energy balance's "escaped" comes out
    negative. It happens within the fill's tolerance (quadrature error; at ``draft``, the ray
    noise of partly occluded pairs: rows 1 +- 5e-3 in a closed room full of boxes). With
    ``s_i = 1 / max(row sum, column share)`` where that exceeds ``1 + tol`` (1 elsewhere), the
    entry ``F_ij min(s_i, s_j)`` keeps ``A_i F_ij = A_j F_ji`` (both sides get the same factor)
    and every row sum is at most ``s_i`` times the old one, so at most 1. Rows that were within
    ``1 + tol`` are never raised, and an entry moves by at most the larger excess of its two rows.

    Returns the bounded matrix (``F`` itself when no row exceeds ``1 + tol``) and the number of
    rows that did.
    """
    area = np.asarray(area, float)
    rows = np.asarray(F.sum(axis=1)).ravel()
    worst = np.maximum(rows, front_share(F, area))
    over = worst > 1.0 + tol
    if not over.any():
        return F, 0
    s = np.ones(F.shape[0])
    s[over] = 1.0 / worst[over]
    F = F.tocsr(copy=True)
    row_of = np.repeat(np.arange(F.shape[0]), np.diff(F.indptr))
    F.data *= np.minimum(s[row_of], s[F.indices])
    return F, int(over.sum())
