"""How long a uniform fill would take, from a sample of its pairs (``method="auto"``).

The fill's cost is not its pair count alone. In a furnished room most facing pairs are partly
occluded, each behind about ten possible occluders, and their exact shadows (unions of hidden
polygons, squares split along penumbrae) cost far more per pair than in the Cornell box, where
a partly occluded pair has about two. Measured on the 2-core machine of FIELD_NOTES
(2026-12-05, one run each, the visibility's seconds against the sample's counts): the
visibility time follows the sum over partly occluded pairs of (possible occluders)^2 at
2.0-2.7 microseconds a unit at ``draft`` (the bundled box cut to 491 and 5,121 patches, the
generated furnished rooms of 2,018 and 5,146 patches: 0.4 s, 8.3 s, 44 s, about 33 min), 6.7 at
``default`` (the box, 1,744 patches: 6.1 s) and 13.5 at ``fine`` (3,300 patches: 22.7 s); the
form factors 1-2 microseconds a facing pair. The sample is seeded: the same scene always gets
the same estimate.

The model can be far off where neither count drives the cost: a closed room of tessellated
spheres, capsules and cylinders (3,247 patches at ``draft``) has about 21 possible occluders a
partly occluded pair, so the model said 11 minutes, but most of those pairs take rays, whose
cost does not grow with the occluders, and the fill took 45 s. So a fill the model calls slow
is timed on a random sample of its rows (:func:`time_fill`) before the hierarchy is taken.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ...visibility import MAYBE, Visibility
from ...visibility._constants import AUTO_EXACT_ATOL
from .assembly import FillSettings, facing_pairs, fill_block

__all__ = ["FillEstimate", "FillTiming", "estimate_fill", "time_fill"]

SAMPLE_PAIRS = 20_000  # random ordered pairs of active patches
# seconds per facing pair and per unit of sum(occluders^2), at draft-like tolerances (rays for
# the small pairs) and below AUTO_EXACT_ATOL (exact shadows for pairs behind few occluders, at
# visibility_atol = EXACT_ATOL; tighter tolerances cost more: the box at fine, 1e-5, took 13.5
# microseconds a unit, so the cost goes as atol^-0.3)
SECONDS_PER_PAIR = {"rays": 1.0e-6, "exact": 1.5e-6}
SECONDS_PER_OCCLUDER2 = {"rays": 2.5e-6, "exact": 7.0e-6}
EXACT_ATOL = 1e-4


@dataclass(frozen=True)
class FillEstimate:
    """Estimated work and time of a uniform fill (unordered pairs of active patches)."""

    facing_pairs: float
    partial_pairs: float
    occluders_squared: float  # sum over partly occluded pairs of (possible occluders)^2
    seconds: float
    sampled: int  # ordered pairs drawn

    def describe(self) -> str:
        """One line for a note: the estimate and what it rests on."""
        share = self.partial_pairs / self.facing_pairs if self.facing_pairs else 0.0
        mean_sq = self.occluders_squared / self.partial_pairs if self.partial_pairs else 0.0
        return (f"about {_duration(self.seconds)} on 2 cores, from {self.sampled:,} sampled pairs: "
                f"{share:.0%} of {self.facing_pairs:.2g} facing pairs partly occluded, "
                f"mean squared count of possible occluders {mean_sq:.3g}")


def estimate_fill(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, visibility: Visibility,
                  settings: FillSettings, active: np.ndarray, samples: int = SAMPLE_PAIRS, seed: int = 0
                  ) -> FillEstimate:
    """Estimate a uniform fill's time from the classification of ``samples`` random pairs."""
    index = np.flatnonzero(active)
    n = len(index)
    if n < 2:
        return FillEstimate(0.0, 0.0, 0.0, 0.0, 0)
    rng = np.random.default_rng(seed)
    i, j = index[rng.integers(0, n, samples)], index[rng.integers(0, n, samples)]
    facing = facing_pairs(quads, normals, centroid, i, j)
    status, rows, _ = visibility.classify(i[facing], j[facing])
    count = np.bincount(rows, minlength=len(status)).astype(float)
    per_pair = n * n / 2 / samples  # each ordered pair drawn (of n^2) stands for this many unordered ones
    n_facing = facing.sum() * per_pair
    partial_pairs = (status == MAYBE).sum() * per_pair
    squared = (count ** 2).sum() * per_pair
    mode = "exact" if settings.visibility == "exact" or settings.visibility_rtol < AUTO_EXACT_ATOL else "rays"
    per_unit = SECONDS_PER_OCCLUDER2[mode]
    if mode == "exact":
        per_unit *= (EXACT_ATOL / max(settings.visibility_rtol, 1e-12)) ** 0.3
    seconds = SECONDS_PER_PAIR[mode] * n_facing + per_unit * squared
    return FillEstimate(float(n_facing), float(partial_pairs), float(squared), float(seconds), samples)


# time_fill: the share of the active rows timed, and the seconds after which it stops with fewer
# (the rows timed by then project the fill all the same, less precisely). Rows differ: on the
# 2,120-face furnished room (5,228 patches) 0.5% of them projected 176 s and 284 s with two
# seeds, 1.6% 355 s and 327 s.
TIMED_ROWS_SHARE = 0.02
TIMED_SECONDS = 5.0


@dataclass(frozen=True)
class FillTiming:
    """A uniform fill's time projected from some of its rows, filled and timed."""

    seconds: float
    rows: int  # rows timed
    share: float  # of the active rows

    def describe(self) -> str:
        return f"timing {self.rows:,} random rows of it ({self.share:.1%}) projects {_duration(self.seconds)}"


def time_fill(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, area: np.ndarray, visibility: Visibility,
              settings: FillSettings, active: np.ndarray, share: float = TIMED_ROWS_SHARE,
              budget: float = TIMED_SECONDS, seed: int = 0) -> FillTiming:
    """Fill random rows of the uniform fill and project its time from theirs.

    Row r of the fill holds the pairs (r, j > r) (:func:`fill_block`), so each unordered pair
    lies in one row and rows drawn uniformly give an unbiased sample of the fill's work. The
    rows are drawn (seeded) from the active ones until ``share`` of them or ``budget`` seconds.
    What the fill builds once is built before the clock starts: the ray tracer's scene here,
    and the closed objects' labels and the kernels it uses by one row filled untimed. Unlike
    :func:`estimate_fill` this depends on the machine and its load: near the threshold the
    choice it informs can differ between runs.
    """
    rows = np.flatnonzero(active)
    if len(rows) < 2:
        return FillTiming(0.0, 0, 0.0)
    order = np.random.default_rng(seed).permutation(rows)
    quads, normals, centroid, area = (np.ascontiguousarray(a, dtype=np.float64) for a in (quads, normals, centroid, area))

    def fill_row(r: int) -> None:
        fill_block(quads, normals, centroid, area, visibility, settings, int(r), int(r) + 1, active=active)

    if visibility.n_occluders:
        visibility._occluder()  # the tracer's scene, as the fill builds it once
    fill_row(order[0])
    want = max(1, math.ceil(share * len(rows)))
    spent, timed = 0.0, 0
    for r in order[1:want + 1]:
        t0 = time.perf_counter()
        fill_row(r)
        spent += time.perf_counter() - t0
        timed += 1
        if spent > budget:
            break
    return FillTiming(spent * len(rows) / timed, timed, timed / len(rows))


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"
