"""Named tolerances of the visibility stage (kept beside it; candidates for ``radiosity._tol``)."""

from __future__ import annotations

# Rays stop this fraction of their length short of the end point (tfar = 1 - this), on top of
# the end's offset off the source surface (``_tol.RAY_OFFSET_REL``).
RAY_TFAR_SHORT = 1e-4

# Pairs with more undecided occluders than this trace their rays through Embree, not the
# compiled loop over their list (Visibility._trace). Measured on two plates 8 x 8 with an
# icosphere between them (4,096 pairs, 256 rays each): 14 occluders a pair, 0.07 s by loop
# against 0.13 s by Embree; 38, 0.22 against 0.21; 242, 0.69 against 0.17; 842, 2.5 against 0.28.
RAY_LIST_EMBREE = 64

# Distance from an occluder's plane, relative to the scene size, within which a patch vertex
# counts as lying in that plane (touching or coplanar). float64 geometry, so far above rounding.
PLANE_REL = 1e-9

# Coplanar occluder patches of one object are merged into one convex polygon when the area of
# their convex hull matches the sum of their areas to this relative accuracy.
MERGE_AREA_REL = 1e-9

# Merged occluder polygons keep at most this many vertices (more: the patches stay separate).
MAX_OCCLUDER_VERTICES = 8
# coplanar occluders of different objects are merged two at a time in planes holding at most
# this many (every two are tried: quadratic)
CROSS_MERGE_MAX = 32

# Occluders per node leaf of the bounding-volume hierarchy used to find a pair's occluders.
BVH_LEAF = 4

# Candidate (pair, occluder) rows examined per chunk (bounds temporary memory, ~0.5 GB).
CHUNK_TRIPLES = 400_000

# Pairs classified per call of the compiled classification (bounds its buffers, ~20 MB).
CHUNK_CLASSIFY = 262_144

# Exact-shadow rows (receiver point, source, occluder) per numpy chunk.
CHUNK_SHADOWS = 100_000

# Pairs' possible occluders (list entries, plus one a pair) per call of the adaptive squares:
# every square of a level carries its pair's list, up to ~5,000 squares a pair behind 80
# occluders, so View3D's 398-surface hall at the defaults, all 3,475 partly occluded pairs in
# one call, held 24 GB when the OOM killer stopped it. About 1 GB at most a chunk.
CHUNK_SQUARE_PAIRS = 4_096

# Most hidden polygons at one receiver point united by the compiled kernels (inclusion-exclusion
# up to _exact_kernel.IE_MAX_POLYGONS, then the sum over the union's boundary, n^2 edge tests);
# more go to shapely. 10 while inclusion-exclusion did it all: 12-sided concentric prisms sent
# points with ~20 to shapely, and their 72-patch view factors took 100 s instead of 33 s. 32 until
# 2026-12-03: in a furnished room at draft 6,017 points went to shapely with 33-62 each. 64 until
# session 21: in View3D's 398-surface hall a wall's points see 100+ fins and ceiling strips, and
# shapely's unions took 1.8-3.7x the compiled sum's time on those pairs (the same factors).
MAX_UNION = 512
# "auto" visibility sends a partly occluded pair to exact shadows whatever its factor when it
# has at most this many possible occluders (no receiver point can need shapely; kept at 32 when
# MAX_UNION went to 64, so the exact pairs of default and fine stayed the same) and
# visibility_atol is below AUTO_EXACT_ATOL, else only if rays would likely miss by more than
# visibility_atol (methods.uniform.assembly). Draft (1e-3) keeps its rays: its rows of F stay
# within its 1e-2 (a 20-box furnace: 0.9975-1.0053 with rays, 0.9997-1.0003 exact) in 0.55-0.6x
# the time.
AUTO_EXACT_OCCLUDERS = 32
AUTO_EXACT_ATOL = 1e-3

# The same for the shadow-aligned cells, whose pairs fall back to fixed points past it: in a
# room full of boxes a point sees the three faces of each of several boxes hide overlapping
# parts of a source (the intersections across boxes are mostly empty and pruned).
MAX_UNION_CELLS = 24

# Kernel weights below this fraction of a pair's largest weight count as zero when deciding
# whether a pair's rays agree (a sample on the receiver's horizon carries no light).
WEIGHT_FLOOR_REL = 1e-12

# Grid of the snap-rounded shapely union used when GEOS's floating overlay fails on a
# degenerate set of hidden polygons, relative to their extent (far below anything that
# matters, far above round-off).
SNAP_REL = 1e-12

# Partly occluded pairs per call of the shadow-aligned cell integration (``_cells_kernel``).
CHUNK_CELL_PAIRS = 65_536

# The exact shadows' Gauss orders aim at this share of the fill's ``formfactor_rtol`` (the
# a-priori bound is not a guarantee; the unoccluded factor's own error adds to it). It holds per
# triangle of the shadow cells, and their errors add: at 0.1 a closed 8-sided prism's cap
# triangles took factors to the walls 7e-7 high (rows 2.9e-6 over 1); at 0.01 the rows are
# within 4.2e-7, for 1.1x the matrix's time.
SHADOW_RTOL_SHARE = 0.01


# Fills whose formfactor_rtol and visibility_rtol are both below this (view_factors' 1e-6 and
# 1e-6) integrate exact shadows over shadow-aligned receiver cells (``_cells_kernel``); the
# presets (visibility_rtol 1e-3 to 1e-5) keep the fixed receiver points, which cost 9 to 25
# points a pair where the cells cost 16 to thousands (the Cornell box's default solve took 39 s
# instead of 17 s with the cells at 16 points a pair). The fine preset (1e-6 and 1e-5) took the
# cells while this was 1e-4: 135 s CPU against 39 s with fixed points for a worst object error
# of 0.0730% against 0.0739% (bundled box, one run each, load ~4).
SHADOW_CELLS_BELOW = 1e-5

# ... and only for pairs with at most this many possible occluders; pairs behind more keep the
# fixed points. The cells test every event line against every occluder: in a closed room with 20
# floating boxes (16 occluders a pair, median) they spent 1,860 points a pair and the 216-patch
# fill took 366 s against seconds with fixed points. 8 since 2026-12-04 (the cells now retry and
# fall back when they run out of points): the furnished office's worst row 4.5e-6 -> 1.1e-6 (the
# same with a bottomless desk and an open-backed cabinet 2.7e-5 -> 3.3e-6) in the same time; a
# closed room of 20 floating cubes (126 patches) 250 s either way, 12-sided prisms 42 -> 47 s.
# 16 since session 16 (the cells 2-4x cheaper a point): the open-backed office 3.35e-6 -> 1.23e-6
# (7.8 s against 9.1 s), the 4-cube room 1.15e-6 -> 8.8e-7 (5.1 s against 4.5 s), the 8-cube
# room 2.78e-6 either way (17.1 s against 19.8 s), the 20-cube room 3.1e-6 in 284 s.
MAX_CELL_OCCLUDERS = 16

# Closed-object culling (``_closed``): winding numbers are taken this far (relative to the scene
# size) in front of each patch, count as integers within WINDING_TOL, and an object is left
# uncut when telling them would take more than WINDING_BUDGET (point, triangle) evaluations.
WINDING_OFFSET_REL = 1e-7
WINDING_TOL = 1e-6
WINDING_BUDGET = 50_000_000

# Exact shadows outside the shadow-aligned cells are integrated on receiver squares refined
# where their SHADOW_CELL_ORDER^2-point rule and their four children's disagree
# (``Visibility.adaptive_hidden``), each pair to this share of the absolute error per factor
# the fill asks for (``assembly._shadow_atol``: visibility_atol in "auto", the tighter of it and
# formfactor_rtol in "exact"). Blocked plates one patch each / 3 x 3 / 5 x 5, default preset's
# tolerances: 2.4e-3 / 2.8e-4 / 1.0e-4 off at the 4 x 4 fixed points this replaced, 1.2e-6 /
# 1.5e-7 / 1.8e-8 now (tests/test_assembly.py). At 0.3 the Cornell box's default fill took
# 10.3 s instead of 14.6 s, but the corpus room's worst row went from 5.7e-4 to 9.8e-4 off.
SHADOW_ATOL_SHARE = 0.1
# ... and this share in fills tight enough for the cells (view_factors, where closed models
# must close to 1e-6): a wall-to-wall pair behind 47 occluders passed at 0.1 with its 2 x 2 rule
# and its children agreeing by chance, 1.3e-6 off. The furnace room of 20 boxes: worst row
# 2.5e-6 -> 1.3e-6 off, 77 s -> 117 s.
SHADOW_ATOL_SHARE_TIGHT = 0.01
SHADOW_CELL_ORDER = 2
# ... down to at most this many levels (1/64 of a side)
SHADOW_MAX_DEPTH = 6
# ... starting from about square cells, at most this many along an elongated patch's length
# (``Visibility._root_cells``).
MAX_ROOT_CELLS = 16
# A receiver point counts as lit (or in full shadow) when its hidden factor is within this
# fraction of its unoccluded factor of 0 (or of all of it): the adaptive squares test a square
# whose points all agree so for a penumbra passing between them.
SATURATED_REL = 1e-9
# ... down to this many levels, and only in fills tight enough for the cells (view_factors):
# 12-sided concentric prisms' worst row went from 1.4e-4 to 6.3e-6 off at 3 levels in the same
# time (38 s -> 36 s); rooms of 8 floating cubes, one patch a face, from 2.1-2.8e-5 at 3 levels
# to 3.2-4.4e-6 at 5 (a penumbra on a wall passing between the points of adjacent walls' squares;
# F(wall -> wall) 1.6e-5 high). The prisms gain nothing past 3 (15 s -> 36 s at 5). In the
# Cornell box's default fill (all levels) it cost over 10 minutes and 10 GB instead of seconds.
SHADOW_PENUMBRA_DEPTH = 6
# ... and in looser fills (the presets, view_factors' --tolerance 1e-5 and above) to this many:
# points all lit or all dark at the root miss a penumbra between them at any tolerance. A floor
# sliver 2.2 m long touching a cylinder's foot saw the north wall 1.5e-3 high at tolerance 1e-4
# (the cylinder's shadow on the sliver passed between the root's points); with one level,
# 2e-5 (session 25).
SHADOW_PENUMBRA_DEPTH_LOOSE = 1
# ... and there the squares may split one level further than SHADOW_MAX_DEPTH (1/128 of a side:
# 8 mm on a 1 m wall). A closed room of 8 floating cubes, one patch a face, has 26-40 cube faces
# behind each wall-to-wall pair (more than the cells take), whose kinks (where a shadow starts,
# ends or overlaps another) lie 1-2 cm apart: with tests to 5 levels and squares to 6,
# F(wall -> wall) erred by up to 2.9e-6 (worst row 2.8e-6 from 1); squares to 7, 8.1e-7 (rows
# 1.9e-6); tests to 6 and squares to 7, 3.6e-7 (rows 3.7e-7), in 2.5x the time (17.4 -> 42.8 s).
# The office of tests/helpers.office_scene: rows 1.1e-6 -> 8.4e-7 from 1.
SHADOW_TIGHT_MAX_DEPTH = 7
# ... where, too, a cell is split when the hidden factor at one of its corners misses the
# polynomial through its children's points by more than its tolerance over this share of its
# area: a kink between the outermost points and the cell's side lies in a band about 0.1 of the
# side wide (order 2: the children's outer points are 0.106 of the side from it).
KINK_BAND = 0.1
# A pair whose patches' widths (sqrt of the area) differ by more than this factor integrates
# its shadow over the smaller patch (``Visibility.receive_on_source``), whatever the penumbra
# rule says: on a 3 m wall the shadows a 0.15 m box face casts through clutter are features a
# few cm wide that passed between the squares' points at every depth (F(face -> wall) 5e-5 off
# at any tolerance, mirrored into the face's row; integrated over the face, 3e-8).
RECEIVE_SMALLER_WIDTHS = 4.0
# ... and the cells' pairs whose lines, cells or unions ran out to ``rtol`` times their factor,
# but never below this absolute error (issue 13's 1e-9 bound for an entry, with margin).
CELL_FALLBACK_ATOL = 1e-10
# A pair whose cells ran out of their point budget first tries again with this many times the
# budget (a floor patch crossed by a partition's foot took 54k points for 1e-11; squares, which
# resolve the jump there at first order, left its factor to a wall 3.6e-4 low).
CELL_RETRY_POINTS = 16
# How a pair's cells ended (``_cells_kernel``): integrated; short of points (a larger budget may
# do: the retry above); short of lines, cells, pieces or compiled unions (no budget will). A pair
# stops at its first shortfall and its value is not used: the hall's pairs behind 20-80 fins ran
# out on 2 of 3, and were integrated in full, then retried in full, before being thrown away.
GOOD, OUT_OF_POINTS, OUT_OF_ROOM = 0, 1, 2
# A pair whose cells' grading was capped (``Visibility._settle_capped``) is integrated again at
# this times its rtol, on both sides, and the side whose results agree better is kept.
CAPPED_RTOL_STEP = 0.01

# Pairs whose rays all carry no weight (every sample on the other patch's horizon) take exact
# shadows at order^2 Gauss points of the receiver instead, at each order of BLIND_ORDERS while
# no point sees the source (``Visibility._blind_fraction``).
BLIND_ORDERS = (4, 16)
