"""Solver options and the presets that trade time for accuracy."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, fields, replace

from ._errors import RadiosityWarning
from ._validate import reject_unknown

__all__ = ["Options", "PRESETS", "DEPRECATED_OPTIONS", "rename_deprecated", "warn_ignored"]

# Old spellings of Options fields (docs/options.md): still accepted, with a RadiosityWarning.
# "rtol" meant three things; the solver's is a relative residual, the visibility one is absolute.
DEPRECATED_OPTIONS = {"rtol": "solver_rtol", "visibility_rtol": "visibility_atol"}


def rename_deprecated(options: dict, what: str = "solve option", *, stacklevel: int = 3,
                      aliases: dict[str, str] = DEPRECATED_OPTIONS) -> dict:
    """``options`` with each deprecated name (a key of ``aliases``) replaced by its new one,
    warning once per name.

    Raises
    ------
    TypeError
        An old name given together with its new one (which value was meant is unclear).
    """
    out = dict(options)
    for old, new in aliases.items():
        if old not in out:
            continue
        if new in out:
            raise TypeError(f"{what} {old!r} is the old name of {new!r}; give only {new!r}")
        warnings.warn(f"{what} {old!r} is deprecated; use {new!r}", RadiosityWarning, stacklevel=stacklevel)
        out[new] = out.pop(old)
    return out


def warn_ignored(name: str, what: str = "solve option", reason: str = "", *, stacklevel: int = 3) -> None:
    """Warn (as :func:`rename_deprecated` does) that the deprecated ``name`` has no effect."""
    why = f" ({reason})" if reason else ""
    warnings.warn(f"{what} {name!r} is deprecated and ignored{why}; leave it out", RadiosityWarning,
                  stacklevel=stacklevel)


@dataclass(frozen=True)
class Options:
    """Every knob of ``solve``; presets fill them, keyword overrides replace single ones.

    Attributes
    ----------
    patch_size_rel : float
        Longest patch edge as a fraction of the scene's bounding-box diagonal (used unless the
        scene was loaded with ``max_patch_size`` or ``max_patch_size`` is given here).
    max_patch_size : float or None
        Longest patch edge in metres; overrides ``patch_size_rel``.
    near_order : int
        Gauss points per direction on the receiver for pairs closer than ``far_separation``.
    far_separation : float
        Distance between centroids over the sum of circumradii beyond which one point is used.
    visibility_samples : int
        Sample points per direction on each patch of a pair that may be blocked, first round
        (``visibility_samples**4`` rays per pair).
    visibility : {"auto", "rays", "exact"}
        Partly occluded pairs: adaptive stratified rays, exact shadow clipping, or exact where
        rays would likely miss by more than ``visibility_atol`` and, when ``visibility_atol`` is
        below 1e-3 (not at draft), for every pair behind at most 32 possible occluders (rays
        for small pairs behind many occluders).
    visibility_max_samples : int
        Points per direction on each patch for pairs whose first-round rays disagree.
    visibility_atol : float
        Absolute error per view factor: what ``"auto"`` accepts from rays, and 10x what the
        adaptive exact shadows of ``"auto"`` aim at (old name ``visibility_rtol``, deprecated).
    formfactor_rtol : float
        Relative accuracy of each unoccluded form factor (adaptive quadrature per pair).
    solver : {"auto", "direct", "bicgstab", "gmres", "jacobi", "gauss-seidel", "progressive"}
    solver_rtol : float
        Relative residual at which iterative solvers stop (old name ``rtol``, deprecated).
    cache : bool
        Reuse form factors stored on disk for the same geometry and accuracy settings.
    workers : int or None
        Fill the view-factor matrix on a local Dask cluster of this many processes
        (:mod:`radiosity.methods.uniform.cluster`; needs ``radiosity[cluster]``). None: in this process.
    scheduler : str or None
        Fill it on the running Dask cluster at this address (``tcp://host:8786``) instead.
    method : {"auto", "uniform", "hierarchical"}
        ``"uniform"`` fills the view-factor matrix of the cut patches; ``"hierarchical"``
        refines element quadtrees and links where they matter (``docs/hierarchical.md``);
        ``"auto"`` takes the hierarchy when the uniform fill would pair too many patches
        (more than ``radiosity.solve.AUTO_MAX_PAIRS``: minutes and gigabytes) or would be slow
        (a sample of its pairs estimates more than ``radiosity.solve.AUTO_MAX_FILL_SECONDS``:
        cluttered rooms), else uniform.
    link_tolerance : float
        Hierarchical only: a link is refined while a bound on the radiosity error it makes
        exceeds this fraction of the scene's mean emitted exitance (emitted power / area).
    leaf_tolerance : float
        Hierarchical only: an element splits (all its links move to its children) while the
        radiosity its links gather, summed at its receiver points, strays from the quadratic
        that carries it onto the leaves below by more than a tenth of this fraction of the
        scene's mean emitted exitance at one of them (its 9 points see less of the fit's error
        than the leaves between them), or from its mean by twice it: the error each level
        pushes onto the leaves, which one link at a time does not bound. 0: off.
    min_element_rel : float
        Hierarchical only: smallest element edge as a fraction of the scene's bounding-box
        diagonal (unless ``min_element_size`` is given).
    min_element_size : float or None
        Hierarchical only: smallest element edge in metres; overrides ``min_element_rel``.
    """

    patch_size_rel: float = 1 / 25
    max_patch_size: float | None = None
    near_order: int = 3
    far_separation: float = 3.0
    visibility_samples: int = 2
    visibility: str = "auto"
    visibility_max_samples: int = 4
    visibility_atol: float = 1e-4
    formfactor_rtol: float = 1e-4
    solver: str = "auto"
    solver_rtol: float = 1e-10
    cache: bool = True
    progress: bool = False
    workers: int | None = None
    scheduler: str | None = None
    method: str = "auto"
    link_tolerance: float = 3e-3
    leaf_tolerance: float = 2e-2
    min_element_rel: float = 1 / 100
    min_element_size: float | None = None

    @classmethod
    def from_preset(cls, preset: str = "default", **overrides) -> "Options":
        """Options of a named preset with some fields replaced."""
        if preset not in PRESETS:
            raise TypeError(f"unknown preset {preset!r}; valid: {', '.join(PRESETS)}")
        overrides = rename_deprecated(overrides, stacklevel=4)
        reject_unknown(overrides, [f.name for f in fields(cls)], "solve option")
        return replace(PRESETS[preset], **overrides)

    # Read-only old names, for readers (the fill's FillSettings) not yet moved to the new ones.
    @property
    def visibility_rtol(self) -> float:
        """Old name of :attr:`visibility_atol` (it is an absolute tolerance)."""
        return self.visibility_atol

    @property
    def rtol(self) -> float:
        """Old name of :attr:`solver_rtol`."""
        return self.solver_rtol


PRESETS = {
    "draft": Options(patch_size_rel=1 / 12, near_order=2, far_separation=2.0, visibility_samples=2,
                     visibility="auto", visibility_max_samples=3, visibility_atol=1e-3, formfactor_rtol=1e-3,
                     link_tolerance=1e-2, leaf_tolerance=3e-2, min_element_rel=1 / 50),
    "default": Options(),
    "fine": Options(patch_size_rel=1 / 35, near_order=4, far_separation=4.0, visibility_samples=3,
                    visibility_max_samples=5, visibility_atol=1e-5, formfactor_rtol=1e-6,
                    link_tolerance=1e-3, leaf_tolerance=1e-2, min_element_rel=1 / 200),
}
