"""A self-contained HTML page of a solution: a small WebGL viewer written inline, no downloads.

The page holds the triangles (one vertex per corner, so each triangle can carry its patch's
id for picking), the tone-mapped sRGB colours and the radiosity of every patch, base64-encoded.
It opens in any browser with WebGL, offline: drag to orbit, wheel to zoom, hover a surface for
its object's and patch's radiosity; a toggle switches between the picture and a false-colour
map of luminous radiosity with its colour bar.
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import numpy as np

__all__ = ["write_html", "write_page", "page_data", "page_data_from_result"]


def _b64(array: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def page_data(solution, *, exposure: float) -> dict:
    """The JSON the page embeds for a Solution (arrays base64, little-endian)."""
    from ..viz import scene_camera
    from .export import triangles

    vertices, tris, patch = triangles(solution)
    return _page(vertices, tris, patch, solution.vertex_mesh[2], solution.radiosity, solution.scene.patch_object,
                 solution.scene.patch_area, solution.scene.objects, scene_camera(solution.scene.source),
                 exposure, Path(solution.scene.source).name)


def page_data_from_result(mesh, record: dict, *, exposure: float) -> dict:
    """The same from a ``solution.vtp`` (pyvista mesh) and its ``summary.json`` (or {})."""
    from ..viz import scene_camera

    faces = _polygons(mesh)
    vertices = np.asarray(mesh.points, dtype=float)
    tris = np.concatenate([np.column_stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]]) for f in faces])
    patch = np.repeat(np.arange(len(faces)), [len(f) - 2 for f in faces])
    a, b, c = (vertices[tris[:, k]] for k in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    keep = area2 > 1e-12 * max(float(np.ptp(vertices, axis=0).max()), 1e-300) ** 2
    tris, patch = tris[keep], patch[keep]
    patch_area = np.bincount(patch, weights=area2[keep] / 2, minlength=len(faces))
    names = [str(n) for n in mesh.field_data["object_names"]] if "object_names" in mesh.field_data else None
    patch_object = np.asarray(mesh.cell_data["object"], dtype=np.int64)
    if names is None:
        names = [f"object {k}" for k in range(int(patch_object.max()) + 1)]
    radiosity = np.asarray(mesh.cell_data["radiosity"], dtype=float)
    source = record.get("source")
    camera = scene_camera(source) if source else None
    return _page(vertices, tris, patch, np.asarray(mesh.point_data["radiosity"], dtype=float), radiosity,
                 patch_object, patch_area, names, camera, exposure, Path(source).name if source else "result")


def _polygons(mesh) -> list[np.ndarray]:
    """The cells of a PolyData as vertex-index arrays."""
    flat = np.asarray(mesh.faces)
    out, i = [], 0
    while i < len(flat):
        n = int(flat[i])
        out.append(flat[i + 1:i + 1 + n])
        i += n + 1
    return out


def _page(vertices, tris, patch, vertex_b, radiosity, patch_object, patch_area, names, camera, exposure,
          source) -> dict:
    from ..solution import object_means
    from ..viz import tone_map

    corners = tris.ravel()
    srgb = tone_map(vertex_b / np.pi, exposure)
    means = object_means(patch_object, patch_area, radiosity, len(names))
    objects = [{"name": str(name), "radiosity": [float(v) for v in mean]} for name, mean in zip(names, means)]
    return {
        "n": int(len(corners)),
        "position": _b64(vertices[corners], "<f4"),
        "colour": _b64(srgb[corners], "u1"),
        "luminance": _b64((vertex_b @ LUMINANCE)[corners], "<f4"),
        "patch": _b64(np.repeat(patch, 3), "<u4"),
        "patch_radiosity": _b64(radiosity, "<f4"),
        "patch_object": _b64(patch_object, "<u4"),
        "objects": objects,
        "camera": None if camera is None else {"position": list(camera[0]), "target": list(camera[1]),
                                               "up": list(camera[2]), "fov": camera[3]},
        "exposure": float(exposure),
        "white": float(np.pi / exposure),  # luminous radiosity shown as white in the picture
        "scale_max": float(np.pi / exposure),  # the false-colour scale tops where the picture is white
        "source": source,
    }


def write_html(solution, path: str | Path, *, exposure: float | None = None) -> None:
    """Write the self-contained viewer page of ``solution`` to ``path``."""
    from ..viz import auto_exposure

    exposure = auto_exposure(solution) if exposure is None else exposure
    write_page(page_data(solution, exposure=exposure), path)


def write_page(data: dict, path: str | Path) -> None:
    """Write the page around ``data`` (from :func:`page_data` or :func:`page_data_from_result`)."""
    from ._files import atomic_path

    text = (_PAGE.replace("__TITLE__", html.escape(f"radiosity: {data['source']}"))
            .replace("__DATA__", json.dumps(data).replace("</", "<\\/")))
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


_PAGE = r"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>__TITLE__</title>
<style>
html, body { margin: 0; height: 100%; background: #111; color: #ddd; font: 13px system-ui, sans-serif; overflow: hidden; }
#view { width: 100%; height: 100%; display: block; cursor: grab; }
#panel { position: absolute; top: 10px; left: 10px; background: rgba(0,0,0,0.6); padding: 8px 10px; border-radius: 4px; }
#tip { position: absolute; pointer-events: none; background: rgba(0,0,0,0.8); padding: 6px 8px; border-radius: 4px; display: none; white-space: pre; }
#bar { position: absolute; right: 16px; top: 50%; transform: translateY(-50%); background: rgba(0,0,0,0.6); padding: 6px; border-radius: 4px; }
#bar canvas { display: block; }
button { font: inherit; }
</style></head>
<body>
<canvas id="view"></canvas>
<div id="panel"><b id="title"></b><br>
drag: orbit, wheel: zoom, hover: values<br>
<button id="mode">show false colour</button></div>
<div id="bar"><div id="barTitle"></div><canvas id="barCanvas" width="90" height="260"></canvas></div>
<div id="tip"></div>
<script id="data" type="application/json">__DATA__</script>
<script>
"use strict";
const D = JSON.parse(document.getElementById("data").textContent);

function decode(b64, Type) {
  const bin = atob(b64), bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer);
}
const position = decode(D.position, Float32Array);
const colour = decode(D.colour, Uint8Array);
const luminance = decode(D.luminance, Float32Array);
const patchOf = decode(D.patch, Uint32Array);
const patchB = decode(D.patch_radiosity, Float32Array);
const patchObject = decode(D.patch_object, Uint32Array);

// Viridis-like ramp (five stops) for the false-colour view and its bar.
const STOPS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
function ramp(t) {
  t = Math.min(1, Math.max(0, t)) * (STOPS.length - 1);
  const i = Math.min(STOPS.length - 2, Math.floor(t)), f = t - i;
  return STOPS[i].map((c, k) => Math.round(c + f * (STOPS[i + 1][k] - c)));
}
const falseColour = new Uint8Array(3 * D.n);
for (let v = 0; v < D.n; v++) {
  const c = ramp(luminance[v] / D.scale_max);
  falseColour.set(c, 3 * v);
}
const ids = new Uint8Array(3 * D.n);  // patch index + 1, as RGB, for picking
for (let v = 0; v < D.n; v++) {
  const id = patchOf[v] + 1;
  ids[3 * v] = id & 255; ids[3 * v + 1] = (id >> 8) & 255; ids[3 * v + 2] = (id >> 16) & 255;
}

// --- small linear algebra (column-major 4x4) ---
function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
function norm(a) { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }
function lookAt(eye, target, up) {
  const z = norm(sub(eye, target)), x = norm(cross(up, z)), y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
          -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
}
function perspective(fovDeg, aspect, near, far) {
  const f = 1 / Math.tan(fovDeg * Math.PI / 360), nf = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
}
function multiply(a, b) {
  const out = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++)
    for (let k = 0; k < 4; k++) out[4 * c + r] += a[4 * k + r] * b[4 * c + k];
  return out;
}

// --- the orbit camera, around the scene's centre (or the scene camera's target) ---
let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
for (let v = 0; v < D.n; v++) for (let k = 0; k < 3; k++) {
  lo[k] = Math.min(lo[k], position[3 * v + k]); hi[k] = Math.max(hi[k], position[3 * v + k]);
}
const size = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;
let target = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2];
let up = [0, 0, 1], fov = 40, eye0 = [target[0] + size, target[1] - size, target[2] + 0.8 * size];
if (D.camera) { target = D.camera.target; up = D.camera.up; fov = D.camera.fov; eye0 = D.camera.position; }
up = norm(up);
const offset = sub(eye0, target);
let distance = Math.hypot(offset[0], offset[1], offset[2]);
// spherical angles about the up axis: a basis (e1, e2, up)
const e1 = norm(Math.abs(up[0]) < 0.9 ? cross(up, [1, 0, 0]) : cross(up, [0, 1, 0])), e2 = cross(up, e1);
let yaw = Math.atan2(dot(offset, e2), dot(offset, e1));
let pitch = Math.asin(Math.max(-1, Math.min(1, dot(offset, up) / distance)));
function eye() {
  const c = Math.cos(pitch);
  return [0, 1, 2].map(k => target[k] + distance * (c * Math.cos(yaw) * e1[k] + c * Math.sin(yaw) * e2[k] + Math.sin(pitch) * up[k]));
}

// --- WebGL ---
const canvas = document.getElementById("view");
const gl = canvas.getContext("webgl", { antialias: true, preserveDrawingBuffer: true });
if (!gl) { document.body.insertAdjacentHTML("beforeend", "<p style='position:absolute;top:40%;width:100%;text-align:center'>This page needs WebGL.</p>"); throw new Error("no WebGL"); }
const VS = "attribute vec3 p; attribute vec3 c; uniform mat4 m; varying vec3 vc;" +
           "void main() { gl_Position = m * vec4(p, 1.0); vc = c; }";
const FS = "precision mediump float; varying vec3 vc; void main() { gl_FragColor = vec4(vc, 1.0); }";
function shader(type, text) {
  const s = gl.createShader(type); gl.shaderSource(s, text); gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}
const program = gl.createProgram();
gl.attachShader(program, shader(gl.VERTEX_SHADER, VS)); gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FS));
gl.linkProgram(program); gl.useProgram(program);
function buffer(data) { const b = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, b); gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW); return b; }
const buffers = { p: buffer(position), picture: buffer(colour), falseColour: buffer(falseColour), id: buffer(ids) };
const locP = gl.getAttribLocation(program, "p"), locC = gl.getAttribLocation(program, "c"), locM = gl.getUniformLocation(program, "m");
gl.enable(gl.DEPTH_TEST);

let mode = "picture";
let pickTarget = null;
function draw(colours, width, height) {
  const m = multiply(perspective(fov, width / height, distance / 100, distance + 4 * size), lookAt(eye(), target, up));
  gl.viewport(0, 0, width, height);
  gl.clearColor(0, 0, 0, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.uniformMatrix4fv(locM, false, new Float32Array(m));
  gl.bindBuffer(gl.ARRAY_BUFFER, buffers.p); gl.enableVertexAttribArray(locP); gl.vertexAttribPointer(locP, 3, gl.FLOAT, false, 0, 0);
  gl.bindBuffer(gl.ARRAY_BUFFER, colours); gl.enableVertexAttribArray(locC); gl.vertexAttribPointer(locC, 3, gl.UNSIGNED_BYTE, true, 0, 0);
  gl.drawArrays(gl.TRIANGLES, 0, D.n);
}
function render() {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; pickTarget = null; }
  draw(mode === "picture" ? buffers.picture : buffers.falseColour, w, h);
}
function pick(x, y) {  // the patch under pixel (x, y), from an offscreen pass coloured by patch id
  const w = canvas.width, h = canvas.height;
  if (!pickTarget) {
    const fb = gl.createFramebuffer(), tex = gl.createTexture(), depth = gl.createRenderbuffer();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, w, h, 0, gl.RGBA, gl.UNSIGNED_BYTE, null);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT16, w, h);
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
    pickTarget = fb;
  }
  gl.bindFramebuffer(gl.FRAMEBUFFER, pickTarget);
  gl.disable(gl.BLEND);
  draw(buffers.id, w, h);
  const px = new Uint8Array(4);
  gl.readPixels(x, h - 1 - y, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  render();
  const id = px[0] + (px[1] << 8) + (px[2] << 16);
  return id - 1;
}

// --- interaction ---
let dragging = null;
canvas.addEventListener("mousedown", e => { dragging = [e.clientX, e.clientY]; canvas.style.cursor = "grabbing"; });
window.addEventListener("mouseup", () => { dragging = null; canvas.style.cursor = "grab"; });
const tip = document.getElementById("tip");
function fmt(v) { return v.map(x => x.toPrecision(4)).join(", "); }
canvas.addEventListener("mousemove", e => {
  if (dragging) {
    yaw -= (e.clientX - dragging[0]) * 0.01;
    pitch = Math.max(-1.5, Math.min(1.5, pitch + (e.clientY - dragging[1]) * 0.01));
    dragging = [e.clientX, e.clientY];
    tip.style.display = "none";
    render();
    return;
  }
  const dpr = window.devicePixelRatio || 1, r = canvas.getBoundingClientRect();
  const p = pick(Math.round((e.clientX - r.left) * dpr), Math.round((e.clientY - r.top) * dpr));
  if (p < 0 || p >= patchObject.length) { tip.style.display = "none"; return; }
  const o = D.objects[patchObject[p]];
  const b = [patchB[3 * p], patchB[3 * p + 1], patchB[3 * p + 2]];
  tip.textContent = o.name + "\nobject mean radiosity (" + fmt(o.radiosity) + ") W/m\u00b2" +
                    "\npatch " + p + " radiosity (" + fmt(b) + ") W/m\u00b2";
  tip.style.left = (e.clientX + 14) + "px"; tip.style.top = (e.clientY + 14) + "px"; tip.style.display = "block";
});
canvas.addEventListener("mouseleave", () => { tip.style.display = "none"; });
canvas.addEventListener("wheel", e => { e.preventDefault(); distance *= Math.exp(e.deltaY * 0.001); render(); }, { passive: false });
window.addEventListener("resize", render);

// --- colour bar: the false-colour scale, or the picture's grey ramp (what maps to white) ---
function drawBar() {
  const bar = document.getElementById("barCanvas"), ctx = bar.getContext("2d");
  const H = bar.height - 20, x0 = 4, w = 18;
  ctx.clearRect(0, 0, bar.width, bar.height);
  const top = mode === "picture" ? D.white : D.scale_max;
  for (let y = 0; y < H; y++) {
    const t = 1 - y / (H - 1);
    let c;
    if (mode === "picture") {
      const s = t <= 0.0031308 ? 12.92 * t : 1.055 * Math.pow(t, 1 / 2.4) - 0.055;
      c = [255 * s, 255 * s, 255 * s].map(Math.round);
    } else { c = ramp(t); }
    ctx.fillStyle = "rgb(" + c.join(",") + ")"; ctx.fillRect(x0, 10 + y, w, 1);
  }
  ctx.fillStyle = "#ddd"; ctx.font = "11px system-ui, sans-serif";
  for (let k = 0; k <= 4; k++) {
    const v = top * (1 - k / 4), y = 10 + k * (H - 1) / 4;
    ctx.fillRect(x0 + w, y, 4, 1); ctx.fillText(v.toPrecision(3), x0 + w + 7, y + 4);
  }
  document.getElementById("barTitle").textContent = mode === "picture" ? "luminous B, W/m\u00b2 (picture)" : "luminous B, W/m\u00b2";
}
document.getElementById("mode").addEventListener("click", e => {
  mode = mode === "picture" ? "false" : "picture";
  e.target.textContent = mode === "picture" ? "show false colour" : "show picture";
  drawBar(); render();
});
document.getElementById("title").textContent = D.source + ", exposure " + D.exposure.toPrecision(3);
drawBar();
render();
document.body.dataset.ready = "1";
</script></body></html>
"""
