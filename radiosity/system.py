"""The radiosity system (I - rho F) B = E per RGB channel, its solvers and energy balance."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ._errors import RadiosityWarning

__all__ = ["SolverReport", "solve_system", "energy_balance", "SOLVERS"]

SOLVERS = ("auto", "direct", "bicgstab", "gmres", "jacobi", "gauss-seidel", "progressive")

# Below this many unknowns a sparse LU is cheaper than setting up a Krylov solve.
DIRECT_MAX = 1500


@dataclass
class SolverReport:
    method: str
    iterations: list[int]
    residual: list[float]  # ||(I - rho F) B - E|| / ||E|| per channel


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
            continue
        if method == "direct":
            x, it = spla.spsolve(A.tocsc(), e), 1
        elif method in ("bicgstab", "gmres"):
            counter = [0]

            def count(_):
                counter[0] += 1

            fn = spla.bicgstab if method == "bicgstab" else spla.gmres
            x, info = fn(A, e, x0=e.copy(), rtol=rtol, atol=0.0, maxiter=1000, callback=count)
            it = counter[0]
            if info != 0:
                warnings.warn(f"{method} did not converge (info={info}); falling back to a direct solve",
                              RadiosityWarning, stacklevel=3)
                x = spla.spsolve(A.tocsc(), e)
        elif method in ("jacobi", "gauss-seidel"):
            x, it = _stationary(F, r, e, rtol, method == "gauss-seidel")
        else:
            x, it = progressive(F, area, r, e, rtol)
        out[:, c] = x
        report.iterations.append(int(it))
        report.residual.append(_relative_residual(A, e, x))
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
