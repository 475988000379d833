"""Named tolerances and chunk sizes: every magic number of the kernels lives here."""

from __future__ import annotations

# Relative size below which a cross product or area counts as zero (degenerate edge or face).
# Relative to the squared edge lengths involved, so it is scale free.
DEGENERATE_REL = 1e-14

# Relative distance (to scene size) by which ray origins and ends are pulled off surfaces.
# Embree works in float32 (eps 6e-8); 1e-5 of the scene's diagonal is ~150 ulps, enough to
# avoid self hits at shared edges yet far below any feature a scene is modelled with.
RAY_OFFSET_REL = 1e-5

# A receiver closer than this to a source's plane (relative to the source's distance) lies in
# that plane and sees the source edge-on: its form factor is 0. ~45 ulp: above the rounding of
# the height itself, so a receiver 1e-13 off the plane still gets its (well conditioned) value.
IN_PLANE_REL = 1e-14

# Distance from a face plane, relative to the face size, within which a polygon counts as planar.
PLANAR_REL = 1e-6

# Pairs of (receiver point, source polygon) evaluated per numpy chunk: bounds temporary memory
# to roughly CHUNK_PAIRS * 8 edges * 3 * 8 bytes * a handful of temporaries (~150 MB).
CHUNK_PAIRS = 200_000

# Rays per embree call: large enough to amortise the call, small enough to stay in cache.
CHUNK_RAYS = 1_000_000

# The tightest relative tolerance a form factor may be asked for (``_validate.check_rtol``).
MIN_RTOL = 1e-12

# View factors below this are dropped from the sparse matrix; the dropped mass is reported.
DROP_FACTOR = 1e-12

# Fraction of the machine's memory a single allocation plan may use before we refuse.
MEMORY_FRACTION = 0.7

# --- Form-factor kernels (radiosity/formfactors/) ---------------------------

# A receiver whose distance to the source's reference vertex exceeds this multiple of the source's
# radius (around that vertex) uses the cancellation-free "far" edge sum: the reference term
# 2·A/|c|² plus per-edge corrections, instead of Lambert's raw sum of O(size/distance) terms
# whose total is O((size/distance)²). Below it the raw sum loses at most a few bits.
FAR_FIELD_RATIO = 2.0

# An edge whose subtended sine is below this uses the arcsin series for θ/sinθ − 1 (four terms)
# instead of atan2: below 0.03 the remainder (0.022 sin^10) is under 1.3e-17, smaller than the
# rounding of theta/sin(theta) - 1 formed from atan2, so the series is also the more accurate.
FAR_SERIES_SINE = 0.03

# A source whose every point is seen below this elevation sine (every edge rises at most this
# far above the receiver's horizon) uses the horizon form of Lambert's sum: per edge the small
# difference between its azimuth swept and its Lambert term, plus 2π times the winding number.
# Lambert's raw terms are O(1) there while F ~ elevation², so the raw sum would lose
# 1/elevation² of its digits (2^8 at 1/16, which the raw sum still affords). The same bound,
# on the receiver's height over the source's plane and on its normal's tilt towards it,
# selects the near-plane form (_lambert._near_plane_sum).
GRAZING_SINE = 1.0 / 16.0

# Receiver-triangle pairs handed to one parallel task of the numba kernels.
KERNEL_BLOCK = 4096

# Adaptive patch-pair quadrature: a pair is accepted when two successive estimates agree to
# rtol·F, or to this absolute floor (form factors below it are dropped from F anyway).
PAIR_ATOL = 1e-14

# Most receiver points the fill spends on one pair (a 64 x 64 Gauss grid). Pairs that touch
# along an edge converge slowly; past this the estimate is kept (error ~1e-6 of the factor on
# the Cornell box), so the cost of a fill stays proportional to its pairs.
PAIR_MAX_POINTS = 4096
