"""Seeded fuzzing of the readers through the command line (issue 19 item 7).

Mutants of the bundled scenes, of the ``.vs3`` models of the View3D tests and of a points file
(``tests/fuzzing.py``) run through ``radiosity.cli.main`` in this process. Every run must end
cleanly: success with finite outputs (the base numbers when the edit keeps the meaning), or exit
2 with one short ``radiosity: error:`` line (always, when the edit makes the input invalid).
``RADIOSITY_FUZZ_COUNT`` multiplies the counts (default 1: 60 OBJ/MTL, 60 .vs3, 40 points);
``bench/fuzz.py`` runs a larger campaign and counts the outcomes.
"""

from __future__ import annotations

import os

import numpy as np

import pytest

import fuzzing

SCALE = max(1, int(os.environ.get("RADIOSITY_FUZZ_COUNT", "1")))
COUNTS = {"obj": 60 * SCALE, "vs3": 60 * SCALE, "points": 40 * SCALE}
SEED = int(os.environ.get("RADIOSITY_FUZZ_SEED", "19"))


@pytest.fixture(autouse=True)
def _bounded_memory(monkeypatch):
    monkeypatch.setenv("RADIOSITY_MEMORY_BUDGET", "2G")  # a mutant must not take the machine's memory


@pytest.mark.parametrize("kind", ["obj", "vs3", "points"])
def test_every_mutant_ends_cleanly(kind):
    bases, bad = {}, []
    for index, mutant in enumerate(fuzzing.mutants(kind, COUNTS[kind], SEED)):
        key = mutant.base
        if mutant.expect == "same" and key not in bases:
            bases[key] = fuzzing.run_mutant(fuzzing.base_mutant(kind, key))
        run = fuzzing.run_mutant(mutant)
        outcome, why = fuzzing.classify(mutant, run, bases.get(key))
        if outcome not in fuzzing.CLEAN_OUTCOMES:
            bad.append(f"{kind}:{index} {mutant.edits} (expect {mutant.expect}): {outcome}: {why}")
    assert not bad, "\n".join(bad)


def test_the_mutator_is_seeded_and_covers_every_expectation():
    a = fuzzing.mutants("obj", 30, 1)
    b = fuzzing.mutants("obj", 30, 1)
    assert [m.files for m in a] == [m.files for m in b]
    expects = {m.expect for kind in ("obj", "vs3", "points") for m in fuzzing.mutants(kind, 40, SEED)}
    assert expects == {"same", "refuse", "any"}


def test_the_classifier_flags_what_is_not_clean():
    mutant = fuzzing.base_mutant("vs3", "plates")
    bad = fuzzing.Mutant("vs3", "plates", mutant.files, mutant.args, "refuse", ["x"])
    ok_run = fuzzing.Run(2, "radiosity: error: plates.vs3:3: bad\n", "")
    assert fuzzing.classify(bad, ok_run)[0] == fuzzing.CLEAN
    assert fuzzing.classify(bad, fuzzing.Run(2, "radiosity: error: " + "x" * 400 + "\n", ""))[0] == fuzzing.TOO_LONG
    assert fuzzing.classify(bad, fuzzing.Run(2, "noise\nradiosity: error: x\n", ""))[0] == fuzzing.TOO_LONG
    assert fuzzing.classify(bad, fuzzing.Run(2, "radiosity: error: something is wrong\n", ""))[0] == fuzzing.TOO_LONG
    assert fuzzing.classify(bad, fuzzing.Run(1, "Traceback (most recent call last):\n", ""))[0] == fuzzing.TRACEBACK
    assert fuzzing.classify(bad, fuzzing.Run(0, "", "", results={}))[0] == fuzzing.ACCEPTED_INVALID
    assert fuzzing.classify(mutant, fuzzing.Run(0, "", "", nonfinite="F.npz[data]"))[0] == fuzzing.NAN_EXIT0
    assert fuzzing.classify(mutant, fuzzing.Run(2, "radiosity: error: x\n", ""))[0] == fuzzing.REFUSED_VALID
    assert fuzzing.classify(mutant, fuzzing.Run(None, "", "", error="timeout"))[0] == fuzzing.HANG


# Findings of the campaign (bench/fuzz.py), each fixed in its reader.

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


@pytest.mark.parametrize("reference", ["1_0", "\u0661", "\uff11", "+\u0661", "1\u0660"])
def test_face_references_are_ascii_integers(tmp_path, reference):
    """int() read 'f 1_0 ...' as vertex 10 and Arabic-Indic or fullwidth digits as digits."""
    import radiosity

    obj = tmp_path / "a.obj"
    obj.write_text(TRIANGLE * 4 + f"f {reference} 2 3\n", encoding="utf-8")
    with pytest.raises(radiosity.SceneError, match=r"a\.obj:13: face 1 has a bad vertex reference"):
        radiosity.load_scene(obj)


@pytest.mark.parametrize("text", [
    "T x\nF 3\nV 1 0 0 " + "9" * 5000 + "z\nE\n",  # not a number
    "T x\n" + "Q" * 100_000 + "\nE\n",  # unknown identifier
    "T x\nF " + "3" * 100_000 + "\nE\n",  # unknown format
    "T x\nF 3\nV 1 0 0\n" + " junk" * 50_000 + "\nE\n",
    "T x\nF 3\nV 1 0 0 0\nS 1 1 1 1" + " x" * 50_000 + "\nE\n",
    "T x\nF 3a\nS 1 " + "R" * 100_000 + " 0 0 0.5 a\nE\n",
])
def test_vs3_messages_quote_a_short_excerpt(tmp_path, text):
    """Records of 100 KB were quoted whole in the error line."""
    import radiosity

    path = tmp_path / "long.vs3"
    path.write_text(text)
    with pytest.raises(radiosity.SceneError) as info:
        radiosity.load_scene(path)
    assert len(str(info.value)) < fuzzing.MAX_MESSAGE and "long.vs3" in str(info.value)


@pytest.mark.parametrize("text", [
    "mtllib " + "x" * 5000 + ".mtl\n" + TRIANGLE + "f 1 2 3\n",
    TRIANGLE + "f " + "a" * 5000 + " 2 3\n",
    "v 0 0 " + "1" * 2000 + "\n",
    "mtllib m.mtl\n" + TRIANGLE + "usemtl " + "q" * 5000 + "\nf 1 2 3\n",
])
def test_obj_messages_quote_a_short_excerpt(tmp_path, text):
    import radiosity

    (tmp_path / "m.mtl").write_text("newmtl grey\nKd 0.5 0.5 0.5\n")
    path = tmp_path / "long.obj"
    path.write_text(text)
    with pytest.raises(radiosity.SceneError) as info:
        radiosity.load_scene(path)
    assert len(str(info.value)) < fuzzing.MAX_MESSAGE and "long.obj" in str(info.value)


@pytest.mark.parametrize("factor", [1e-150, 1e-160, 1e-300])
def test_a_tiny_base_with_subsurfaces_is_refused_or_cut(tmp_path, factor):
    """Scaled by 1e-300, the room's south wall has an area that underflows; cutting its door
    out used to end in a GEOSException (an internal error) instead of naming the surface."""
    import re

    import radiosity
    from helpers import ROOM_VS3 as ROOM

    def scale(match):
        return match[1] + "".join(f" {float(x) * factor!r}" for x in match.groups()[1:])

    scaled = re.sub(r"^(V \d+) (\S+) (\S+) (\S+)", scale, ROOM, flags=re.M)
    path = tmp_path / "tiny.vs3"
    path.write_text(scaled)
    try:
        scene = radiosity.load_scene(path)
    except radiosity.SceneError as exc:
        assert re.search(r"tiny\.vs3:\d+: surface \d+ \(\w+\) has zero area", str(exc))
    else:
        assert np.isfinite(scene.patch_area).all() and (scene.patch_area > 0).all()


@pytest.mark.parametrize("geometry", ["1 1 0   0 0   1e200 1", "1e300 1 0   0 0   1 1", "1 1 0   0 0   1e9 2e9"])
def test_3a_shapes_are_bounded_like_vertices(tmp_path, geometry):
    """An F 3a rectangle 1e200 wide overflowed to an OverflowError (internal error) when cut."""
    import radiosity

    path = tmp_path / "wide.vs3"
    path.write_text(f"T wide\nF 3a\nS 1 R 0 0 0.5 floor\n  {geometry}\nE\n")
    with pytest.raises(radiosity.SceneError, match=r"wide\.vs3:3: surface 1 has a corner beyond 1e\+09"):
        radiosity.load_scene(path)


def test_a_self_crossing_subsurface_is_refused_by_name(tmp_path):
    """A door corner moved to x = 5e-324 made the door's outline cross itself; GEOS's
    TopologyException came out as an internal error."""
    import radiosity
    from helpers import ROOM_VS3 as ROOM

    path = tmp_path / "crossed.vs3"
    path.write_text(ROOM.replace("V 11 1.4 0 2", "V 11 5e-324 0 2"))
    with pytest.raises(radiosity.SceneError, match=r"crossed\.vs3:\d+: (sub)?surface \d+ \(\w+\).*simple polygon"):
        radiosity.load_scene(path)
