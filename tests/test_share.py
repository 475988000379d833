"""Taking a result elsewhere: a .glb with radiosity in vertex colours, a self-contained HTML page."""

from __future__ import annotations

import base64
import json
import re
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

import radiosity
from radiosity.cli import main
from radiosity.io.export import linear_colours, triangles, write_glb
from radiosity.io.html import page_data, write_html
from radiosity.viz import auto_exposure

from helpers import ROOM
RUN_PAGE = Path(__file__).parent / "js" / "run_page.js"


@pytest.fixture(scope="module")
def solution():
    return radiosity.solve(radiosity.load_scene(ROOM), preset="draft", cache=False)


def _glb_json(path: Path) -> dict:
    blob = path.read_bytes()
    magic, version, _ = struct.unpack("<4sII", blob[:12])
    assert magic == b"glTF" and version == 2
    length, kind = struct.unpack("<I4s", blob[12:20])
    assert kind == b"JSON"
    return json.loads(blob[20:20 + length])


def test_glb_round_trips_through_trimesh(solution, tmp_path):
    import trimesh

    path = tmp_path / "solution.glb"
    exposure = auto_exposure(solution)
    write_glb(solution, path, exposure=exposure)
    loaded = trimesh.load(path, process=False)
    assert isinstance(loaded, trimesh.Scene)
    assert sorted(loaded.geometry) == sorted(solution.scene.objects)
    vertices, tris, patch = triangles(solution)
    vertex_b = solution.vertex_mesh[2]
    tri_object = solution.scene.patch_object[patch]
    for index, name in enumerate(solution.scene.objects):
        mesh = loaded.geometry[name]
        used = np.unique(tris[tri_object == index])
        np.testing.assert_allclose(mesh.vertices, vertices[used], atol=1e-6)
        assert len(mesh.faces) == (tri_object == index).sum()
        colour = np.asarray(mesh.visual.vertex_attributes["color"])[:, :3]
        expected = np.round(255 * linear_colours(vertex_b[used] / np.pi, exposure))
        np.testing.assert_array_equal(colour, expected)
        np.testing.assert_allclose(mesh.vertex_attributes["_RADIOSITY"], vertex_b[used], rtol=1e-6)
    tree = _glb_json(path)
    assert "KHR_materials_unlit" in tree["extensionsUsed"]
    assert all(p["material"] == 0 and "COLOR_0" in p["attributes"] for m in tree["meshes"] for p in m["primitives"])


def test_glb_reads_in_pyvista(solution, tmp_path):
    """VTK's glTF reader (what ParaView uses) sees every object with its colours."""
    import pyvista as pv

    path = tmp_path / "solution.glb"
    write_glb(solution, path)
    blocks = [b for b in pv.read(path).recursive_iterator() if b is not None]
    assert len(blocks) == len(solution.scene.objects)
    assert all("COLOR_0" in b.point_data and "_RADIOSITY" in b.point_data for b in blocks)
    total = sum(b.n_cells for b in blocks)
    assert total == len(triangles(solution)[1])


def _embedded(page: Path) -> dict:
    text = page.read_text()
    blob = re.search(r'<script id="data" type="application/json">(.*?)</script>', text, re.S).group(1)
    return json.loads(blob.replace("<\\/", "</"))


def test_html_page_is_self_contained_and_holds_the_solution(solution, tmp_path):
    page = tmp_path / "page.html"
    write_html(solution, page)
    text = page.read_text()
    assert "<script src" not in text and not re.search(r"(src|href)=[\"']?(https?:)?//", text)
    data = _embedded(page)
    vertices, tris, patch = triangles(solution)
    assert data["n"] == 3 * len(tris)
    radiosity_ = np.frombuffer(base64.b64decode(data["patch_radiosity"]), "<f4").reshape(-1, 3)
    np.testing.assert_allclose(radiosity_, solution.radiosity, rtol=1e-6)
    corners = np.frombuffer(base64.b64decode(data["patch"]), "<u4")
    np.testing.assert_array_equal(corners, np.repeat(patch, 3))
    assert [o["name"] for o in data["objects"]] == solution.scene.objects
    means = solution.object_radiosity()
    for o in data["objects"]:
        np.testing.assert_allclose(o["radiosity"], means[o["name"]], rtol=1e-9)
    assert data == page_data(solution, exposure=auto_exposure(solution))


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_html_script_runs_picks_and_shows_values(solution, tmp_path):
    """The page's own script, in node with stub DOM and WebGL: it draws, frames the scene, and a
    hover over patch 3 shows patch 3's object and values."""
    page = tmp_path / "page.html"
    write_html(solution, page)
    report = json.loads(subprocess.run(["node", str(RUN_PAGE), str(page)], check=True, capture_output=True,
                                       text=True, timeout=60).stdout)
    assert report["ready"] and report["draws"] >= 1 and report["lastCount"] == report["n"]
    assert report["insideFraction"] > 0.95
    name = solution.scene.objects[solution.scene.patch_object[3]]
    assert report["tipShown"] == "block" and report["tip"].startswith(name)
    assert f"{solution.radiosity[3, 0]:.4g}"[:4] in report["tip"]
    assert report["tipOnBackground"] == "none"
    assert report["modeButton"] == "show picture" and report["drawsAfter"] > report["draws"]


def test_cli_solve_html_and_view_html(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "--html", "-o", str(out)]) == 0
    assert "solution.html" in capsys.readouterr().out
    assert {"solution.glb", "solution.html"} <= {p.name for p in out.iterdir()}
    page = tmp_path / "again.html"
    assert main(["view", str(out), "--html", str(page)]) == 0
    a, b = _embedded(out / "solution.html"), _embedded(page)
    assert [o["name"] for o in b["objects"]] == [o["name"] for o in a["objects"]]
    for x, y in zip(a["objects"], b["objects"]):
        np.testing.assert_allclose(y["radiosity"], x["radiosity"], rtol=1e-5)
    assert b["exposure"] == pytest.approx(a["exposure"])


CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (.ci/run installs it)")
def test_html_page_in_headless_chromium(solution, tmp_path):
    from PIL import Image

    page = tmp_path / "page.html"
    write_html(solution, page)
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                    "--enable-unsafe-swiftshader", "--window-size=640,480", "--virtual-time-budget=5000",
                    f"--screenshot={shot}", page.as_uri()], check=True, capture_output=True, timeout=120)
    pixels = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    middle = pixels[120:360, 160:480]
    assert middle.std() > 5 and middle.max() > 40  # the lit room, not a blank page
