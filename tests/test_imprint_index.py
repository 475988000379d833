"""Imprinting's candidate search (imprint._Candidates) gives exactly what all pairs give."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import radiosity
from radiosity.imprint import imprint_faces
from radiosity.io.obj import read_obj

CORPUS = sorted((Path(__file__).parent / "data" / "corpus").glob("*.obj"))
# corners 0-3 at the bottom, 4-7 above them; faces wound outwards, the bottom first
BOX = [f[::-1] for f in ([0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0])]


def _same(vertices, faces, face_object, max_patch_size=None) -> None:
    """Indexed and all-pairs imprints agree exactly: contacts, pieces, patches."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        fast = imprint_faces(vertices, faces, face_object)
        slow = imprint_faces(vertices, faces, face_object, _all_pairs=True)
    assert [(c.face, c.other_object, c.kind, c.hidden, c.area) for c in fast.contacts] == \
        [(c.face, c.other_object, c.kind, c.hidden, c.area) for c in slow.contacts]
    for a, b in zip(fast.contacts, slow.contacts):
        np.testing.assert_array_equal(a.outline, b.outline)
    np.testing.assert_array_equal(fast.vertices, slow.vertices)
    assert len(fast.pieces) == len(slow.pieces)
    for a, b in zip(fast.pieces, slow.pieces):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(fast.piece_face, slow.piece_face)
    np.testing.assert_array_equal(fast.piece_hidden, slow.piece_hidden)


def _data(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        return read_obj(path)


def test_cornell_same_as_all_pairs():
    data = _data(radiosity.bundled_scene("cornell_box"))
    _same(data.vertices, data.faces, data.face_object)


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: p.stem)
def test_corpus_same_as_all_pairs(path):
    data = _data(path)
    _same(data.vertices, data.faces, data.face_object)


def test_cornell_patches_same_as_all_pairs(monkeypatch):
    """Through load_scene: the patch arrays are equal element for element."""
    import radiosity.imprint as imprint

    cornell = radiosity.bundled_scene("cornell_box")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        fast = radiosity.load_scene(cornell, max_patch_size=0.1)
        original = imprint.imprint_faces
        monkeypatch.setattr(imprint, "imprint_faces", lambda *a, **k: original(*a, _all_pairs=True, **k))
        slow = radiosity.load_scene(cornell, max_patch_size=0.1)
    np.testing.assert_array_equal(fast.patch_quads, slow.patch_quads)
    np.testing.assert_array_equal(fast.patch_face, slow.patch_face)
    np.testing.assert_array_equal(fast.patch_hidden, slow.patch_hidden)


def _boxes(rng: np.random.Generator, n: int, *, bottomless: bool):
    """n axis-aligned boxes (one object each) resting on a floor of 3 x 3 tiles, some on
    each other, some touching sideways, with grid-snapped sizes so contacts are exact."""
    vertices = [np.array([[x, 0, z] for z in (0, 1, 2, 3) for x in (0, 1, 2, 3)], float)]
    faces = [np.array([4 * j + i, 4 * (j + 1) + i, 4 * (j + 1) + i + 1, 4 * j + i + 1])
             for j in range(3) for i in range(3)]
    face_object = [0] * 9
    count = 16
    for k in range(n):
        lo = rng.integers(0, 10, 3) / 4.0
        lo[1] = rng.choice([0.0, 0.5, 0.25 * rng.integers(0, 8)])
        size = rng.integers(1, 5, 3) / 4.0
        hi = lo + size
        corners = np.array([[lo[0], lo[1], lo[2]], [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]], [hi[0], lo[1], lo[2]],
                            [lo[0], hi[1], lo[2]], [lo[0], hi[1], hi[2]], [hi[0], hi[1], hi[2]], [hi[0], hi[1], lo[2]]])
        vertices.append(corners)
        for face in BOX[1:] if bottomless and k % 2 else BOX:
            faces.append(np.array(face) + count)
            face_object.append(k + 1)
        count += 8
    return np.concatenate(vertices), faces, np.array(face_object)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7), bottomless=st.booleans())
def test_random_boxes_same_as_all_pairs(seed, n, bottomless):
    vertices, faces, face_object = _boxes(np.random.default_rng(seed), n, bottomless=bottomless)
    _same(vertices, faces, face_object)


def test_tile_inside_bottomless_footprint_is_found():
    """A floor tile wholly inside a bottomless block's outline: no edge of the block meets the
    tile's box, yet the tile is covered (the candidate search works per object)."""
    tile = np.array([[1.4, 0, 1.4], [1.4, 0, 1.6], [1.6, 0, 1.6], [1.6, 0, 1.4]])
    lo, hi = np.array([1.0, 0.0, 1.0]), np.array([2.0, 1.0, 2.0])
    corners = np.array([[lo[0], lo[1], lo[2]], [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]], [hi[0], lo[1], lo[2]],
                        [lo[0], hi[1], lo[2]], [lo[0], hi[1], hi[2]], [hi[0], hi[1], hi[2]], [hi[0], hi[1], lo[2]]])
    vertices = np.concatenate([tile, corners])
    faces = [np.arange(4)] + [np.array(f) + 4 for f in BOX[1:]]
    cut = imprint_faces(vertices, faces, np.array([0] + [1] * 5), scale=4.0)
    assert cut.piece_hidden[cut.piece_face == 0].all()
    _same(vertices, faces, np.array([0] + [1] * 5))


def test_cli_no_imprint_reaches_load_scene(monkeypatch):
    """--no-imprint (shared by solve, viewfactors, exchange) loads with imprint=False."""
    import argparse

    from radiosity.cli import _common

    seen = {}
    monkeypatch.setattr(_common, "load_scene", lambda path, **options: seen.update(options))
    parser = argparse.ArgumentParser()
    _common.add_scene_args(parser, optional_scene=True)
    _common.load(parser.parse_args(["--no-imprint"]))
    assert seen["imprint"] is False
    seen.clear()
    _common.load(parser.parse_args([]))
    assert seen.get("imprint", True) is True


def test_no_imprint_scene_has_no_hidden_patches():
    cornell = radiosity.bundled_scene("cornell_box")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        on = radiosity.load_scene(cornell)
        off = radiosity.load_scene(cornell, imprint=False)
    assert on.patch_hidden.any() and not off.patch_hidden.any()
    np.testing.assert_allclose(on.patch_area.sum(), off.patch_area.sum(), rtol=1e-12)


def test_objects_apart_need_no_parts():
    """Boxes standing apart: no contacts, every face whole, same as all pairs."""
    rng = np.random.default_rng(3)
    vertices, faces, face_object = _boxes(rng, 1, bottomless=False)
    far = vertices.copy()
    far[16:] += [10.0, 5.0, 10.0]  # the box leaves the floor's box
    cut = imprint_faces(far, faces, face_object)
    assert not cut.contacts and len(cut.pieces) == len(faces)
    _same(far, faces, face_object)
