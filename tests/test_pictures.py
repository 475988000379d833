"""Pictures: the tone map as documented, and white balance to the light for picture.png only."""

from __future__ import annotations

import json

import numpy as np
import pytest

import radiosity
from radiosity.cli import main
from radiosity.viz import light_gains, tone_map, white_balanced


def test_tone_map_is_exposure_clip_and_srgb():
    x = np.linspace(0, 1.5, 301)[:, None].repeat(3, axis=1)
    out = tone_map(x, 1.0)
    assert out.dtype == np.uint8 and out[0, 0] == 0 and (out[x[:, 0] >= 1] == 255).all()
    assert (np.diff(out[:, 0].astype(int)) >= 0).all()
    # the sRGB curve: 18% grey is 118, the linear toe below 0.0031308
    assert tone_map(np.full((1, 3), 0.18), 1.0)[0, 0] == 118
    assert tone_map(np.full((1, 3), 0.002), 1.0)[0, 0] == round(255 * 12.92 * 0.002)
    np.testing.assert_array_equal(tone_map(x, 2.0), tone_map(2 * x, 1.0))


def test_light_gains_make_the_light_grey_at_the_same_luminance():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    solution = radiosity.Solution(scene=scene, radiosity=scene.emission.copy(), F=None)
    gains = light_gains(solution)
    light = scene.emission[scene.emission.any(axis=1)][0]
    np.testing.assert_allclose(light, [17 * np.pi, 12 * np.pi, 4 * np.pi])
    balanced = light * gains
    assert np.ptp(balanced) < 1e-9 * balanced.max()  # grey
    luminance = np.array([0.2126, 0.7152, 0.0722])
    assert balanced @ luminance == pytest.approx(light @ luminance)
    shown, g = white_balanced(solution)
    np.testing.assert_allclose(shown.radiosity, solution.radiosity * g)
    assert shown is not solution and solution.radiosity[scene.emission.any(axis=1)][0, 2] == pytest.approx(4 * np.pi)


def _centre_colour(path):
    from PIL import Image

    pixels = np.asarray(Image.open(path).convert("RGB")).astype(float)
    h, w, _ = pixels.shape
    return pixels[h // 4: h // 2, w // 3: 2 * w // 3].reshape(-1, 3).mean(axis=0)  # the back wall


def test_white_balance_changes_the_picture_only(tmp_path, capsys):
    runs = {}
    for mode in ("none", "light"):
        out = tmp_path / mode
        assert main(["solve", "--preset", "draft", "--white-balance", mode, "-o", str(out)]) == 0
        runs[mode] = out
    capsys.readouterr()
    warm, neutral = _centre_colour(runs["none"] / "picture.png"), _centre_colour(runs["light"] / "picture.png")
    assert warm[0] / warm[2] > 1.5  # the measured light's yellow
    assert neutral[0] / neutral[2] < 1.25  # near grey (the white paint, Kd 0.725 0.71 0.68, is a little warm)
    a, b = (json.loads((runs[m] / "summary.json").read_text()) for m in ("none", "light"))
    assert a["objects"] == b["objects"] and a["exposure"] == b["exposure"]
    assert "white_balance" not in a and b["white_balance"]["applies_to"] == "picture.png only"
    assert (runs["none"] / "solution.ply").read_bytes() == (runs["light"] / "solution.ply").read_bytes()


def test_the_picture_leaves_out_hidden_patches(tmp_path):
    """Two overlapping coplanar table tops facing the same way: imprint hides the overlap on
    one of them, and the picture draws only the other (drawn both, they z-fought in streaks)."""
    from radiosity.viz import _render_mesh, to_polydata

    obj = tmp_path / "tops.obj"
    obj.write_text("mtllib tops.mtl\n"
                   "o top_a\nusemtl wood\nv 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\nf 1 2 3 4\n"
                   "o top_b\nusemtl wood\nv 0.5 0 0.5\nv 0.5 0 1.5\nv 1.5 0 1.5\nv 1.5 0 0.5\nf 5 6 7 8\n"
                   "o lamp\nusemtl lamp\nv 0 2 0\nv 1 2 0\nv 1 2 1\nv 0 2 1\nf 9 10 11 12\n")
    (tmp_path / "tops.mtl").write_text("newmtl wood\nKd 0.5 0.4 0.3\nnewmtl lamp\nKd 0 0 0\nKe 5 5 5\n")
    scene = radiosity.load_scene(obj)
    hidden = scene.patch_hidden
    assert np.isclose(scene.patch_area[hidden].sum(), 0.25)  # the overlap, on one top only
    solution = radiosity.Solution(scene=scene, radiosity=np.ones((scene.n_patches, 3)), F=None)
    mesh = _render_mesh(solution)
    assert np.isclose(mesh.area, scene.patch_area[~hidden].sum())
    assert to_polydata(solution).cell_data["hidden"].sum() == hidden.sum()
