"""Solver options and the presets that trade time for accuracy."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from ._validate import reject_unknown

__all__ = ["Options", "PRESETS"]


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
        Partly occluded pairs: adaptive stratified rays, exact shadow clipping, or exact only
        where rays would likely miss by more than ``visibility_rtol``.
    visibility_max_samples : int
        Points per direction on each patch for pairs whose first-round rays disagree.
    visibility_rtol : float
        Absolute error per view factor that ``"auto"`` accepts from rays.
    formfactor_rtol : float
        Relative accuracy of each unoccluded form factor (adaptive quadrature per pair).
    solver : {"auto", "direct", "bicgstab", "gmres", "jacobi", "gauss-seidel", "progressive"}
    rtol : float
        Relative residual at which iterative solvers stop.
    cache : bool
        Reuse form factors stored on disk for the same geometry and accuracy settings.
    workers : int or None
        Fill the view-factor matrix on a local Dask cluster of this many processes
        (:mod:`radiosity.methods.uniform.cluster`; needs ``radiosity[cluster]``). None: in this process.
    scheduler : str or None
        Fill it on the running Dask cluster at this address (``tcp://host:8786``) instead.
    method : {"uniform", "hierarchical"}
        ``"uniform"`` fills the view-factor matrix of the cut patches; ``"hierarchical"``
        refines element quadtrees and links where they matter (``docs/hierarchical.md``).
    link_tolerance : float
        Hierarchical only: a link is refined while a bound on the radiosity error it makes
        exceeds this fraction of the scene's mean emitted exitance (emitted power / area).
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
    visibility_rtol: float = 1e-4
    formfactor_rtol: float = 1e-4
    solver: str = "auto"
    rtol: float = 1e-10
    cache: bool = True
    progress: bool = False
    workers: int | None = None
    scheduler: str | None = None
    method: str = "uniform"
    link_tolerance: float = 3e-3
    min_element_rel: float = 1 / 100
    min_element_size: float | None = None

    @classmethod
    def from_preset(cls, preset: str = "default", **overrides) -> "Options":
        """Options of a named preset with some fields replaced."""
        if preset not in PRESETS:
            raise TypeError(f"unknown preset {preset!r}; valid: {', '.join(PRESETS)}")
        reject_unknown(overrides, [f.name for f in fields(cls)], "solve option")
        return replace(PRESETS[preset], **overrides)


PRESETS = {
    "draft": Options(patch_size_rel=1 / 12, near_order=2, far_separation=2.0, visibility_samples=2,
                     visibility="rays", visibility_max_samples=3, visibility_rtol=1e-3, formfactor_rtol=1e-3,
                     link_tolerance=1e-2, min_element_rel=1 / 50),
    "default": Options(),
    "fine": Options(patch_size_rel=1 / 35, near_order=4, far_separation=4.0, visibility_samples=3,
                    visibility_max_samples=5, visibility_rtol=1e-5, formfactor_rtol=1e-6,
                    link_tolerance=1e-3, min_element_rel=1 / 200),
}
