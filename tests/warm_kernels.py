"""Compile the numba kernels once, before the test workers start (``conftest.pytest_configure``).

On a fresh checkout every kernel compiles on first use, and under ``pytest -n 2`` both workers
compiled the same kernels at the same moments, and so did CLI subprocesses started before a
kernel reached the disk cache: about 530 s of CI's 857 s. These shares run two at a time
instead, each compiling its own kernels, and the workers then load the machine code from disk.

    python tests/warm_kernels.py fill     # one share (see SHARES and PHASES)

Each share runs tiny scenes: numba compiles per argument type, not per size.
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

# A unit plate facing up, one facing down 1 above it, and a blocker between them (exact shadows
# through the shadow-aligned cells of view_factors).
PLATES_OBJ = """\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 0 1 1
v 1 1 1
v 1 0 1
v 0.25 0.25 0.5
v 0.25 0.75 0.5
v 0.75 0.75 0.5
v 0.75 0.25 0.5
g bottom
f 1 2 3 4
g top
f 5 6 7 8
g blocker
f 9 10 11 12
f 12 11 10 9
"""


def warm_fill() -> None:
    from radiosity._kernels import warm_up

    warm_up()


def warm_formfactors() -> None:
    import radiosity

    square = np.array([[0.0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    radiosity.point_to_polygons(np.zeros((2, 3)), np.tile([0.0, 0, 1], (2, 1)), [square, square[:3]])
    radiosity.polygon_to_polygon(square - [0, 0, 1], square[::-1])


def warm_view_factors() -> None:
    import radiosity

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plates.obj"
        path.write_text(PLATES_OBJ)
        radiosity.view_factors(radiosity.load_scene(path), cache=False)


def warm_sensors() -> None:
    import radiosity

    box = radiosity.load_scene(radiosity.bundled_scene("cornell_box"), max_patch_size=0.3)
    solution = radiosity.solve(box, preset="draft", cache=False)
    solution.irradiance(np.array([[0.0, 0.01, 0.0], [0.2, 0.01, -0.1]]), np.array([[0.0, 1, 0], [0, 1, 0]]))
    radiosity.solve(box, method="hierarchical", preset="draft", cache=False)


SHARES = {"fill": warm_fill, "formfactors": warm_formfactors, "view_factors": warm_view_factors,
          "sensors": warm_sensors}
# Run in this order, the shares of a phase side by side. The second phase's shares call the
# classification and fill kernels too: by then the fill share has written them to disk.
PHASES = (("fill", "formfactors"), ("view_factors", "sensors"))


def main(share: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        SHARES[share]()


if __name__ == "__main__":
    main(sys.argv[1])
