"""Where the emitters' light first lands: on the front of faces, on their back, or nowhere.

Radiosity counts light that lands on the back of a (one-sided) face as lost, like light that
leaves through an opening: both end up in the energy balance's "escaped". To tell the two apart,
and to catch faces wound the wrong way, we trace a fixed number of rays from the emitters
(points uniform on each emitter patch, patches picked in proportion to their emitted power,
directions cosine-distributed about the front normal, as the emitted light is) and classify each
ray's first hit. The same rays mirrored to the emitters' back sides probe what is behind them.

A float64 Möller-Trumbore test of every triangle for each ray (numpy on small scenes, a
compiled numba loop on large ones; the tests compare the two): the ray count is fixed
(``N_RAYS``), so the cost is linear in the number of triangles and independent of the
visibility backend; loading traces the scene's faces, not its patches.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ._lightpaths_chunks import arrival_side, chunk_boxes, first_hits_chunked, hit_distance

__all__ = ["LightPaths", "trace_emitters", "N_RAYS"]

# Rays per side. The shares are fractions of N_RAYS: 1024 rays give them to about +-1.5%
# (one standard deviation at 50%), plenty for the thresholds below.
N_RAYS = 1024
# Rays x triangles tested per numpy chunk (each costs about 200 bytes of temporaries).
_CHUNK = 1_000_000
# Ray origins leave the surface by this fraction of the scene size; hits nearer are ignored.
_OFFSET_REL = 1e-6
# Up to this many ray-triangle tests numpy is as quick as loading the compiled kernel (about
# 0.5 s once per process), so small scenes never pay for it.
_NUMPY_TESTS = 4_000_000
# From this many triangles on, runs of them are skipped by their boxes (``_lightpaths_chunks``;
# the same hits as the plain kernel).
_CHUNKED_FROM = 4096
# Fixed seed: the same scene always gives the same shares and notes.
_SEED = 20261201


@dataclass
class LightPaths:
    """Shares (of the emitted power) of the emitters' rays by what they first hit.

    ``front``, ``back``, ``escaped`` sum to 1; ``back_objects`` splits ``back`` by object name.
    ``probe_*`` are the same for the rays mirrored to the emitters' back sides.
    """

    n_rays: int
    front: float
    back: float
    escaped: float
    back_objects: dict[str, float] = field(default_factory=dict)
    probe_front: float = 0.0
    probe_back: float = 0.0
    probe_escaped: float = 1.0

    def as_dict(self) -> dict:
        return {"rays": self.n_rays, "front": round(self.front, 4), "back": round(self.back, 4),
                "escaped": round(self.escaped, 4),
                "back_objects": {k: round(float(v), 4) for k, v in self.back_objects.items()}}


def _triangles(quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, 3, 3) triangles of the patches and (t,) their patch index (a fan of each quad)."""
    is_tri = (quads[:, 3] == quads[:, 2]).all(axis=1)
    first = quads[:, [0, 1, 2]]
    second = quads[~is_tri][:, [0, 2, 3]]
    owner = np.concatenate([np.arange(len(quads)), np.flatnonzero(~is_tri)])
    return np.concatenate([first, second]), owner


def _sample_rays(quads, normals, power, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins, unit directions (cosine about the normal) and source patches of N_RAYS rays."""
    cdf = np.cumsum(power) / power.sum()
    u = (np.arange(N_RAYS) + rng.random(N_RAYS)) / N_RAYS  # stratified over the emitted power
    patch = np.minimum(np.searchsorted(cdf, u, side="right"), len(power) - 1)
    s, t = rng.random((2, N_RAYS, 1))
    q = quads[patch]
    origins = (1 - s) * (1 - t) * q[:, 0] + s * (1 - t) * q[:, 1] + s * t * q[:, 2] + (1 - s) * t * q[:, 3]
    n = normals[patch]
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    a = np.cross(n, helper)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(n, a)
    r, phi = np.sqrt(rng.random(N_RAYS))[:, None], 2 * np.pi * rng.random(N_RAYS)[:, None]
    directions = r * np.cos(phi) * a + r * np.sin(phi) * b + np.sqrt(np.maximum(0.0, 1 - r * r)) * n
    return origins, directions, patch


@njit(cache=True)
def _first_hits_kernel(origins, directions, v0, e1, e2, offset, hit, side):  # pragma: no cover - compiled
    for r in range(len(origins)):  # serial: a threaded kernel takes ~1 s to load per process
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        best_t = np.inf
        best = -1
        for k in range(len(v0)):
            t = hit_distance(ox, oy, oz, dx, dy, dz, v0, e1, e2, k)
            if offset < t < best_t:
                best_t = t
                best = k
        hit[r] = best
        if best >= 0:
            side[r] = arrival_side(dx, dy, dz, e1, e2, best)


def _first_hits(origins, directions, triangles, offset, prepared=None) -> tuple[np.ndarray, np.ndarray]:
    """Index of the first triangle hit by each ray (-1: none) and ``dot(direction, e1 x e2)``
    (positive: the ray arrives at the triangle's back). ``prepared``: :func:`_prepare` of the
    triangles, when they are traced more than once."""
    if len(origins) * len(triangles) <= _NUMPY_TESTS:
        return _first_hits_numpy(origins, directions, triangles, offset)
    return _first_hits_compiled(origins, directions, triangles, offset, prepared)


def _prepare(triangles) -> tuple:
    """(v0, e1, e2, boxes) of the compiled kernels: the edges, and the run boxes if chunked."""
    triangles = np.ascontiguousarray(triangles, dtype=np.float64)
    v0 = np.ascontiguousarray(triangles[:, 0])
    e1 = np.ascontiguousarray(triangles[:, 1] - v0)
    e2 = np.ascontiguousarray(triangles[:, 2] - v0)
    return v0, e1, e2, chunk_boxes(v0, e1, e2) if len(triangles) >= _CHUNKED_FROM else None


def _first_hits_compiled(origins, directions, triangles, offset, prepared=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_first_hits` through the compiled kernel."""
    v0, e1, e2, boxes = _prepare(triangles) if prepared is None else prepared
    hit = np.full(len(origins), -1, dtype=np.int64)
    side = np.zeros(len(origins))
    origins = np.ascontiguousarray(origins, dtype=np.float64)
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    if len(v0) >= _CHUNKED_FROM:
        first_hits_chunked(origins, directions, v0, e1, e2, float(offset), hit, side, boxes)
    else:
        _first_hits_kernel(origins, directions, v0, e1, e2, float(offset), hit, side)
    return hit, side


def _first_hits_numpy(origins, directions, triangles, offset) -> tuple[np.ndarray, np.ndarray]:
    """Index of the first triangle hit by each ray (-1: none) and ``dot(direction, e1 x e2)``
    (positive: the ray arrives at the triangle's back)."""
    v0 = triangles[:, 0]
    e1 = triangles[:, 1] - v0
    e2 = triangles[:, 2] - v0
    hit = np.full(len(origins), -1, dtype=np.int64)
    side = np.zeros(len(origins))
    step = max(1, _CHUNK // max(len(triangles), 1))
    for start in range(0, len(origins), step):
        o, d = origins[start:start + step, None, :], directions[start:start + step, None, :]
        p = np.cross(d, e2[None])
        det = np.einsum("rtc,tc->rt", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - v0[None]
            u = np.einsum("rtc,rtc->rt", s, p) * inv
            q = np.cross(s, e1[None])
            v = np.einsum("rtc,rtc->rt", np.broadcast_to(d, q.shape), q) * inv
            t = np.einsum("rtc,tc->rt", q, e2) * inv
            # inside the errstate: a ray parallel to a triangle (det 0) makes u + v inf - inf
            ok = (np.abs(det) > 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > offset)
        t = np.where(ok, t, np.inf)
        best = np.argmin(t, axis=1)
        found = np.isfinite(t[np.arange(len(t)), best])
        hit[start:start + step] = np.where(found, best, -1)
        normal = np.cross(e1[best], e2[best])
        side[start:start + step] = np.einsum("rc,rc->r", directions[start:start + step], normal)
    return hit, side


def _classify(hit, side, triangle_patch, patch_object, objects) -> tuple[float, float, float, dict]:
    n = len(hit)
    found = hit >= 0
    back = found & (side > 0)  # travelling along the normal: it arrives from behind
    names: dict[str, float] = {}
    if back.any():
        counts = np.bincount(patch_object[triangle_patch[hit[back]]], minlength=len(objects))
        for k in np.argsort(-counts, kind="stable"):
            if counts[k]:
                names[objects[k]] = float(counts[k] / n)
    return float((found & ~back).sum() / n), float(back.sum() / n), float((~found).sum() / n), names


def trace_emitters(quads: np.ndarray, normals: np.ndarray, emission: np.ndarray, area: np.ndarray,
                   patch_object: np.ndarray, objects: list[str], scale: float) -> LightPaths | None:
    """Trace N_RAYS rays from the emitters' fronts (and mirrored, their backs); None if nothing emits.

    Parameters
    ----------
    quads : (n, 4, 3) float
        Patches, metres; triangles repeat their third vertex.
    normals : (n, 3) float
        Unit front normals.
    emission : (n, 3) float
        Emitted exitance per channel, W/m^2.
    area : (n,) float
        Patch areas, m^2.
    patch_object : (n,) int
        Object index of each patch.
    objects : list of str
    scale : float
        Scene size, metres.

    Returns
    -------
    LightPaths or None
    """
    power = area * emission.sum(axis=1)
    if not (power > 0).any():
        return None
    rng = np.random.default_rng(_SEED)
    triangles, triangle_patch = _triangles(quads)
    origins, directions, _ = _sample_rays(quads, normals, np.where(power > 0, power, 0.0), rng)
    # Hits nearer than the offset are the ray's own patch (or round-off on a neighbour).
    offset = _OFFSET_REL * max(scale, 1e-300)
    compiled = len(origins) * len(triangles) > _NUMPY_TESTS
    prepared = _prepare(triangles) if compiled else None  # once for both sides
    front_hit, front_side = _first_hits(origins, directions, triangles, offset, prepared)
    probe_hit, probe_side = _first_hits(origins, -directions, triangles, offset, prepared)
    f, b, e, names = _classify(front_hit, front_side, triangle_patch, patch_object, objects)
    pf, pb, pe, _ = _classify(probe_hit, probe_side, triangle_patch, patch_object, objects)
    return LightPaths(N_RAYS, f, b, e, names, pf, pb, pe)


# A note when at least this share of the emitted light first lands on the back of faces.
BACK_SHARE_NOTE = 0.05
# Inside-out: the enclosed side lets at most this share escape and sends at least
# INSIDE_OUT_BACK of its rays to back faces; or the front lets at least INSIDE_OUT_ESCAPE escape.
# INSIDE_OUT_BACK is a majority, not "all": objects inside an inverted room (wound right) still
# catch some of the light on their fronts.
INSIDE_OUT_OPEN = 0.02
INSIDE_OUT_BACK = 0.5
INSIDE_OUT_ESCAPE = 0.9

_WINDING = ("faces emit, reflect and receive only on the side their normal points to (counter-clockwise "
            "winding seen from that side)")


def _pct(x: float) -> str:
    return f"{100 * x:.0f}%"


def _objects_text(names: dict[str, float]) -> str:
    items = [f"{k} {_pct(v)}" for k, v in list(names.items())[:5]]
    return ", ".join(items) + (f" and {len(names) - 5} more object(s)" if len(names) > 5 else "")


def light_path_notes(paths: LightPaths | None, source: str) -> list[str]:
    """Notes on light lost to back faces: a room wound inside-out, or faces facing away.

    Inside-out: the emitters' light lands almost only on back faces with almost nothing
    escaping (a closed room whose faces point out, lit by a correct light), or almost all of it
    escapes while the emitters' back sides face a closed shell of back faces (the light is wound
    like the room: both point out). Otherwise a share above ``BACK_SHARE_NOTE`` on back faces
    names the objects it lands on.
    """
    if paths is None:
        return []
    where = f"{source}: " if source else ""
    measured = f"(of {paths.n_rays} rays from the emitters, weighted by emitted power)"
    enclosed_front = paths.escaped <= INSIDE_OUT_OPEN and paths.back >= INSIDE_OUT_BACK
    enclosed_back = (paths.escaped >= INSIDE_OUT_ESCAPE and paths.probe_escaped <= INSIDE_OUT_OPEN
                     and paths.probe_back >= INSIDE_OUT_BACK)
    if enclosed_front:
        return [f"{where}the scene looks wound inside-out: {_pct(paths.back)} of the emitted light lands on the "
                f"back of faces {measured}: {_objects_text(paths.back_objects)}; it counts as escaped; "
                f"{_WINDING}: reverse the winding of the room's faces (f 1 2 3 4 -> f 4 3 2 1)"]
    if enclosed_back:
        return [f"{where}the scene looks wound inside-out: {_pct(paths.escaped)} of the emitted light escapes "
                f"{measured}, while the emitters' back sides face a closed shell of faces that point away from "
                f"them ({_pct(paths.probe_back)} of the mirrored rays land on back faces); {_WINDING}: reverse "
                "the winding of the room's faces and of the lights (f 1 2 3 4 -> f 4 3 2 1)"]
    if paths.back >= BACK_SHARE_NOTE:
        return [f"{where}{_pct(paths.back)} of the emitted light first lands on the back of faces {measured}, "
                f"where it counts as escaped: {_objects_text(paths.back_objects)}; {_WINDING}: check the "
                "winding of those faces"]
    return []
