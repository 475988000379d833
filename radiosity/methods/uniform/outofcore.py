"""``solve`` when the view-factor matrix does not fit the memory budget: fill F into shards, iterate.

:func:`radiosity.solve` keeps F in memory when the fill's worst case fits the budget
(:func:`radiosity._memory.check_fill`). When it does not, instead of refusing, it fills F out
of core (:func:`radiosity.methods.uniform.shards.write_shards`, blocks planned from the budget) into a temporary
shard folder and solves (I - rho F) B = E by an iterative method whose only use of F is the
matrix-vector product, one pass over the shards each. The three RGB channels share every pass:
the unknown is B (n, 3) as one vector of 3n, each channel scaled to unit norm so one relative
tolerance holds for each. Only when not even the out-of-core fill fits is the in-memory refusal
raised.

The shard folder is removed when the matrix (``Solution.F``) is garbage-collected; it is not
cached, so every such solve fills F again.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from ... import _memory
from ..._errors import MemoryBudgetError, RadiosityError
from .system import accepted_residual

__all__ = ["out_of_core_plan", "solve_shards", "OUT_OF_CORE_SOLVERS"]

# Solvers that need F only through F @ X; "auto" is gmres (one pass over the shards per iteration).
OUT_OF_CORE_SOLVERS = ("auto", "gmres", "bicgstab", "jacobi")
GMRES_RESTART = 60
MAXITER = 1000


def out_of_core_plan(n_patches: int, refusal: MemoryBudgetError) -> int:
    """Pairs per block of the out-of-core fill; ``refusal`` (the in-memory one) if none fits."""
    try:
        return _memory.plan_fill_block(n_patches)
    except MemoryBudgetError:
        raise refusal from None


def _channel_operator(F, rho: np.ndarray, passes: list[int]) -> spla.LinearOperator:
    """(I - rho F) on B (n, 3) flattened to 3n: one pass over F for all channels."""
    n = F.shape[0]

    def apply(x):
        b = np.asarray(x, float).reshape(n, -1)
        passes[0] += 1
        return (b - rho * (F @ b)).reshape(x.shape)

    return spla.LinearOperator((rho.size, rho.size), matvec=apply, dtype=np.float64)


def _residuals(F, rho, e, b) -> list[float]:
    """||(I - rho F) B - E|| / ||E|| per channel (one pass)."""
    r = b - rho * (F @ b) - e
    norms = np.linalg.norm(e, axis=0)
    return [float(np.linalg.norm(r[:, c]) / norms[c]) if norms[c] > 0 else float(np.linalg.norm(r[:, c]))
            for c in range(e.shape[1])]


def solve_shards(F, rho: np.ndarray, emission: np.ndarray, *, method: str = "auto", rtol: float = 1e-10
                 ) -> tuple[np.ndarray, dict]:
    """B (n, 3) of (I - rho F) B = E with F used only as ``F @ X`` (e.g. a ShardedViewFactors).

    Parameters
    ----------
    F : ShardedViewFactors or sparse matrix
        Anything with ``.shape`` and ``F @ X`` for X (n, 3).
    rho, emission : (n, 3) float
    method : {"auto", "gmres", "bicgstab", "jacobi"}
        ``auto`` is gmres (restarted every 60 iterations), one pass over F per iteration;
        bicgstab takes two; jacobi (B <- E + rho F B) one, but converges only as fast as the
        reflectances let light fade.
    rtol : float
        Relative residual asked of each channel.

    Returns
    -------
    B : (n, 3) float
    info : dict
        ``method``, ``iterations``, ``passes`` (over F), ``residual`` per channel.

    Raises
    ------
    RadiosityError
        If a channel's residual ends above :func:`radiosity.methods.uniform.system.accepted_residual`.
    """
    if method not in OUT_OF_CORE_SOLVERS:
        raise ValueError(f"solver {method!r} needs F in memory; out of core: {', '.join(OUT_OF_CORE_SOLVERS)}")
    method = "gmres" if method == "auto" else method
    rho = np.asarray(rho, float)
    e = np.asarray(emission, float)
    scale = np.linalg.norm(e, axis=0)
    scale[scale == 0] = 1.0
    target = e / scale  # each lit channel at unit norm: one tolerance for each
    passes, iterations = [0], [0]
    if method == "jacobi":
        b = _jacobi(F, rho, target, rtol, passes, iterations)
    else:
        A = _channel_operator(F, rho, passes)

        def count(_):
            iterations[0] += 1

        kwargs = {"restart": GMRES_RESTART, "callback_type": "pr_norm"} if method == "gmres" else {}
        solver = spla.gmres if method == "gmres" else spla.bicgstab
        # The flat residual is at most sqrt(3) rtol for unit-norm channels: ask that much less.
        x, _ = solver(A, target.ravel(), x0=target.ravel().copy(), rtol=rtol / np.sqrt(e.shape[1]), atol=0.0,
                      maxiter=MAXITER, callback=count, **kwargs)
        b = x.reshape(e.shape)
    b = b * scale
    residual = _residuals(F, rho, e, b)
    passes[0] += 1
    if not all(np.isfinite(residual)) or max(residual) > accepted_residual(rtol):
        raise RadiosityError(f"{method} over the view-factor shards stopped at relative residual "
                             f"{max(residual):.1e} (asked {rtol:g}) after {iterations[0]} iterations")
    return np.clip(b, 0.0, None), {"method": method, "iterations": iterations[0], "passes": passes[0],
                                   "residual": residual}


def _jacobi(F, rho, e, rtol, passes, iterations) -> np.ndarray:
    b = e.copy()
    norm = np.linalg.norm(e)
    for _ in range(MAXITER * 10):
        step = e + rho * (F @ b)
        passes[0] += 1
        iterations[0] += 1
        change = np.linalg.norm(step - b)  # the residual of the previous iterate
        b = step
        if change <= rtol * norm:
            break
    return b
