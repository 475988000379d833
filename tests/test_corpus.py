"""A corpus of exporter-style OBJ files (tests/data/corpus/), each solved end to end at draft.

The files are written the way exporters write them: Blender's n-gons with ``vt``/``vn`` and
smoothing groups, CRLF line ends with negative indices and ``g`` groups, duplicate coincident
faces, non-planar quads, millimetre coordinates. Each solve must give finite radiosity and a
plausible energy balance: emitted = absorbed + escaped, nothing escapes a closed room, and
"escaped" is never negative. ``make_corpus.py`` in that folder rewrites the files.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import radiosity

CORPUS = Path(__file__).parent / "data" / "corpus"

# name: (load options, closed, objects expected)
CASES = {
    "blender_ngon_room": ({}, True, {"Room", "Lamp", "Box"}),
    "lshape_room_crlf": ({}, True, {"floor", "ceiling", "walls", "lamp"}),
    "duplicate_faces": ({}, False, {"floor", "block", "lamp"}),
    "nonplanar_terrain": ({}, False, {"terrain", "lamp"}),
    "millimetre_box": ({"units": "mm"}, False, {"floor", "ceiling", "walls", "block", "light"}),
    "closed_room_boxes": ({}, True, {"room", "box_floor", "box_wall", "box_float", "lamp"}),
}

# Share of the emitted power a closed room may report as escaped at draft (row sums of F to
# 1e-2 at draft: issue 12 item 4).
CLOSED_ESCAPE = 1e-2


def _solve(name: str, options: dict):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = radiosity.load_scene(CORPUS / f"{name}.obj", **options)
        solution = radiosity.solve(scene, preset="draft", cache=False)
    notes = [str(w.message) for w in caught if issubclass(w.category, radiosity.RadiosityWarning)]
    return scene, solution, notes


@pytest.fixture(scope="module", params=sorted(CASES))
def solved(request):
    name = request.param
    options, closed, objects = CASES[name]
    scene, solution, notes = _solve(name, options)
    return name, closed, objects, scene, solution, notes


def _energy(solution) -> dict[str, np.ndarray]:
    return {k: np.asarray(v, float) for k, v in solution.energy.items()}


def test_objects_and_finite_radiosity(solved):
    name, _, objects, scene, solution, _ = solved
    assert set(scene.objects) == objects
    assert np.isfinite(solution.radiosity).all() and (solution.radiosity >= 0).all()
    means = solution.object_radiosity()
    assert all(np.isfinite(v).all() for v in means.values())
    lit = [k for k, v in means.items() if v.max() > 0]
    assert len(lit) >= 2, f"{name}: only {lit} are lit"


# Closed rooms whose draft view factors have rows summing above 1: -0.21% of the emitted power
# escaped (closed_room_boxes), -0.10% (blender_ngon_room), -0.003% (lshape_room_crlf), from
# draft's 16 rays per partly occluded pair (rows scatter by +-5e-3, within draft's 1e-2,
# test_energy_balance). solve now scales those rows down to 1 with their reciprocal entries
# (system.bound_rows) and names them (Solution.energy_gaining).
ROWS_ABOVE_ONE = {"blender_ngon_room", "closed_room_boxes", "lshape_room_crlf"}


def test_energy_balance(solved):
    name, closed, _, _, solution, _ = solved
    e = _energy(solution)
    assert (e["emitted"] > 0).all()
    np.testing.assert_allclose(e["absorbed"] + e["escaped"], e["emitted"], rtol=1e-9)
    share = e["escaped"] / e["emitted"]
    if closed:
        assert (np.abs(share) < CLOSED_ESCAPE).all(), f"{name}: a closed room lets {share} escape"
    else:
        assert (share > 0.01).all(), f"{name}: an open scene must let light out"


def test_escaped_is_never_negative(solved):
    name, _, _, _, solution, _ = solved
    e = _energy(solution)
    assert (e["escaped"] >= -1e-9 * e["emitted"]).all(), f"{name}: escaped {e['escaped']}"
    rows = np.asarray(solution.F.sum(axis=1)).ravel()
    assert rows.max() <= 1.0 + 1e-9, f"{name}: a row of the solved F sums to {rows.max()}"
    if name in ROWS_ABOVE_ONE:  # the fill left rows above 1: they are named, and were bounded
        assert solution.rows_bounded > 0 and solution.energy_gaining
        assert solution.summary()["rows_bounded"] == solution.rows_bounded


def test_duplicate_faces_are_noted(solved):
    name, _, _, _, _, notes = solved
    if name != "duplicate_faces":
        pytest.skip("the duplicate-faces file only")
    assert any("duplicate" in n.lower() or "coincident" in n.lower() for n in notes), notes


def test_every_face_faces_its_room(solved):
    """Closed rooms' surfaces (not the objects inside) face the room's centre of mass."""
    name, closed, _, scene, _, _ = solved
    if not closed or name == "lshape_room_crlf":  # the L is not convex: the centre test does not apply
        pytest.skip("convex closed rooms only")
    room = scene.patch_object == scene.objects.index({"blender_ngon_room": "Room"}.get(name, "room"))
    centre = scene.patch_centroid[room].mean(axis=0)
    facing = np.einsum("nc,nc->n", scene.patch_normal[room], centre - scene.patch_centroid[room])
    assert (facing > 0).all()


def test_units_mm_match_metres(solved):
    name, _, _, scene, _, _ = solved
    if name != "millimetre_box":
        pytest.skip("the millimetre file only")
    extent = np.ptp(scene.patch_quads.reshape(-1, 3), axis=0)
    np.testing.assert_allclose(extent.max(), 1.0, rtol=1e-9)


def test_nonplanar_quads_are_noted(solved):
    name, _, _, _, _, notes = solved
    if name != "nonplanar_terrain":
        pytest.skip("the terrain file only")
    assert any("not planar" in n for n in notes), notes


def test_crlf_negative_indices_read_like_plain_text(tmp_path):
    """The CRLF / negative-index file gives the same geometry as its LF twin with positive indices."""
    text = (CORPUS / "lshape_room_crlf.obj").read_bytes().decode()
    lines, count, out = text.split("\r\n"), 0, []
    for line in lines:
        if line.startswith("v "):
            count += 1
        if line.startswith("f "):
            line = "f " + " ".join(str(count + 1 + int(r)) for r in line.split()[1:])
        out.append(line)
    plain = tmp_path / "lshape_room_crlf.obj"
    plain.write_text("\n".join(out))
    (tmp_path / "corpus.mtl").write_text((CORPUS / "corpus.mtl").read_text())
    a = radiosity.load_scene(CORPUS / "lshape_room_crlf.obj")
    b = radiosity.load_scene(plain)
    np.testing.assert_array_equal(a.patch_quads, b.patch_quads)
    assert a.objects == b.objects


def test_cli_solves_the_millimetre_file(tmp_path):
    from radiosity.cli import main

    out = tmp_path / "out"
    code = main(["solve", str(CORPUS / "millimetre_box.obj"), "--units", "mm", "--preset", "draft",
                 "--no-picture", "-o", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["objects"]) == CASES["millimetre_box"][2]
    assert all(np.isfinite(v).all() for v in summary["objects"].values())
