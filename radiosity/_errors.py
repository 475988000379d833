"""Exception and warning classes shared by every stage of the pipeline."""

from __future__ import annotations


class RadiosityError(Exception):
    """Base class of every error this package raises on purpose."""


class SceneError(RadiosityError, ValueError):
    """A scene file or scene description is unusable; the message names the file and line."""


class MemoryBudgetError(RadiosityError, MemoryError):
    """A request would need more memory than the machine has; the message gives the estimate."""


class RadiosityWarning(UserWarning):
    """A recoverable surprise (a non-planar face split, a solver stopped early)."""
