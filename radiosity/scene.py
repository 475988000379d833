"""Scene: named objects, per-patch materials and the patches themselves; ``load_scene``."""

from __future__ import annotations

import hashlib
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from . import _memory
from ._checks import _named, duplicate_faces, material_notes
from ._lightpaths import light_path_notes, trace_emitters
from ._errors import RadiosityWarning, SceneError
from ._validate import reject_unknown
from .geometry import centroids_and_areas, polygon_normals
from .io.obj import read_obj
from .imprint import subdivide_imprinted
from .patches import FaceReport, Patches, planar_parts, subdivide_faces, used_vertices

__all__ = ["Scene", "load_scene", "bundled_scene"]

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
EMISSION_MODES = ("radiance", "exitance")
LOAD_OPTIONS = ("units", "allow_clamp", "imprint")


# A scene whose box lies farther from the origin than this many times its size is solved moved
# to the origin (Scene.centred): float64 coordinates of a 1 mm box 1e6 m away resolve 1.2e-10 m,
# 1e-7 of its size and coarser than the visibility's plane tolerance (1e-9 of the scene), and
# 10-13% of the light escaped such a closed box. Nearer, the coordinates are used as they are.
CENTRE_BEYOND_SIZES = 100.0


@dataclass(frozen=True, eq=False)
class Scene:
    """A scene cut into patches, ready for the form-factor stage.

    Attributes
    ----------
    objects : list of str
        Object names (``o`` or ``g`` in the OBJ), in file order.
    patch_quads : (n, 4, 3) float
        Patch vertices, metres; triangles repeat their third vertex.
    patch_object : (n,) int
        Index into ``objects`` of each patch.
    patch_face : (n,) int
        Index of the OBJ face each patch was cut from.
    reflectance : (n, 3) float
        Diffuse reflectance rho per patch and RGB channel, in [0, 1).
    emission : (n, 3) float
        Emitted exitance E per patch, W/m^2.
    emission_mode : {"radiance", "exitance"}
        How the MTL's ``Ke`` was read (E = pi Ke, or E = Ke).
    light_paths : dict or None
        Where the emitters' light first lands: shares ``front``, ``back``, ``escaped`` of
        ``rays`` rays and ``back_objects`` (see ``docs/errors.md``); None if nothing emits.
    """

    objects: list[str]
    patch_quads: np.ndarray
    patch_object: np.ndarray
    patch_face: np.ndarray
    reflectance: np.ndarray
    emission: np.ndarray
    max_patch_size: float | None = None
    source: str = ""
    face_line: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    notes: tuple[str, ...] = ()
    # View3D obstructions: patches that block light but exchange none (see io/view3d.py).
    patch_obstruction: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    # Patches covered by another object (floor under a block, ceiling behind a light; see
    # imprint.py): they can neither receive nor send light. (n,) bool, all False by default.
    patch_hidden: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    # The model declares a closed enclosure (View3D ``encl=1``): ``enforce="auto"`` closes it.
    enclosure: bool = False
    # How the MTL's Ke was read: "radiance" (E = pi Ke) or "exitance" (E = Ke); see load_scene.
    emission_mode: str = "radiance"
    # Where the emitters' light first lands (front/back of faces, escaped), from _lightpaths.
    light_paths: dict | None = None

    def __post_init__(self):
        if len(self.patch_obstruction) != len(self.patch_quads):
            object.__setattr__(self, "patch_obstruction", np.zeros(len(self.patch_quads), bool))
        if len(self.patch_hidden) != len(self.patch_quads):
            object.__setattr__(self, "patch_hidden", np.zeros(len(self.patch_quads), bool))

    @property
    def n_patches(self) -> int:
        return len(self.patch_quads)

    @property
    def patch_inactive(self) -> np.ndarray:
        """(n,) bool: patches that exchange no light, View3D obstructions and hidden regions
        (under a block, behind a light). The solves leave them out; their radiosity is their
        own emission."""
        return self.patch_obstruction | self.patch_hidden

    @cached_property
    def _centroid_area(self) -> tuple[np.ndarray, np.ndarray]:
        return centroids_and_areas(self.patch_quads)

    @property
    def patch_area(self) -> np.ndarray:
        """(n,) patch areas, m^2."""
        return self._centroid_area[1]

    @property
    def patch_centroid(self) -> np.ndarray:
        """(n, 3) area centroids, metres."""
        return self._centroid_area[0]

    @cached_property
    def patch_normal(self) -> np.ndarray:
        """(n, 3) unit normals (front side)."""
        return polygon_normals(self.patch_quads)

    @cached_property
    def scale(self) -> float:
        """Length of the scene's bounding-box diagonal, metres."""
        pts = self.patch_quads.reshape(-1, 3)
        return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))

    @cached_property
    def geometry_hash(self) -> str:
        """Hash of the patch geometry alone: the key of the form-factor cache."""
        digest = hashlib.sha256(np.ascontiguousarray(self.patch_quads, dtype=np.float64).tobytes())
        return digest.hexdigest()[:32]

    def centred(self) -> tuple["Scene", np.ndarray]:
        """The scene moved so that its bounding box is centred on the origin, and the offset (3,)
        that moves it back (:meth:`moved`); the scene itself and zeros when its box lies within
        ``CENTRE_BEYOND_SIZES`` of its sizes from the origin."""
        if not self.n_patches:
            return self, np.zeros(3)
        pts = self.patch_quads.reshape(-1, 3)
        origin = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        if np.abs(origin).max() <= CENTRE_BEYOND_SIZES * self.scale:
            return self, np.zeros(3)
        return replace(self, patch_quads=self.patch_quads - origin), origin

    def moved(self, offset) -> "Scene":
        """The scene translated by ``offset`` (3,), metres."""
        offset = np.asarray(offset, float)
        return replace(self, patch_quads=self.patch_quads + offset) if offset.any() else self

    def with_materials(self, reflectance=None, emission=None) -> "Scene":
        """The same geometry with new per-patch reflectance and/or emission (cache stays valid)."""
        rho = self.reflectance if reflectance is None else np.broadcast_to(np.asarray(reflectance, float), (self.n_patches, 3)).copy()
        em = self.emission if emission is None else np.broadcast_to(np.asarray(emission, float), (self.n_patches, 3)).copy()
        _check_materials(rho, em, self.source)
        return replace(self, reflectance=rho, emission=em)

    def object_material(self, name: str, *, reflectance=None, emission=None) -> "Scene":
        """A copy with one object's reflectance and/or emitted exitance replaced."""
        if name not in self.objects:
            raise KeyError(f"no object {name!r}; objects: {', '.join(self.objects)}")
        mask = self.patch_object == self.objects.index(name)
        rho, em = self.reflectance.copy(), self.emission.copy()
        if reflectance is not None:
            rho[mask] = reflectance
        if emission is not None:
            em[mask] = emission
        return self.with_materials(rho, em)

    def resubdivided(self, max_patch_size: float) -> "Scene":
        """The scene cut again so no patch edge exceeds ``max_patch_size`` (materials follow)."""
        faces, owner = self._faces_to_cut()
        patches, _ = subdivide_faces(self.patch_quads.reshape(-1, 3), faces, max_patch_size)
        parent = owner[patches.patch_face]
        return replace(self, patch_quads=patches.quads, patch_object=self.patch_object[parent],
                       patch_obstruction=self.patch_obstruction[parent], patch_hidden=self.patch_hidden[parent],
                       patch_face=self.patch_face[parent], reflectance=self.reflectance[parent],
                       emission=self.emission[parent], max_patch_size=max_patch_size)

    def _faces_to_cut(self) -> tuple[list[np.ndarray], np.ndarray]:
        """Patches as faces (indices into ``patch_quads.reshape(-1, 3)``) and their patch index.

        A non-planar quad arrives as its two fan triangles ``v0 v1 v2``, ``v0 v2 v3`` (one after
        the other, same face): they are cut as the quad again, so that the cells meet vertex to
        vertex across the fold (``patches._fold_cells``) instead of leaving a crease.
        """
        quads = self.patch_quads
        n = len(quads)
        is_triangle = (quads[:, 3] == quads[:, 2]).all(axis=1)
        # Candidate pairs (i, i + 1) on arrays; a per-patch loop took seconds on 581k patches.
        pair = (is_triangle[:-1] & is_triangle[1:] & (self.patch_face[:-1] == self.patch_face[1:])
                & (self.patch_hidden[:-1] == self.patch_hidden[1:])
                & (quads[:-1, 0] == quads[1:, 0]).all(axis=1) & (quads[:-1, 2] == quads[1:, 1]).all(axis=1))
        folded: list[int] = []
        for i in np.flatnonzero(pair).tolist():  # left to right: a patch joins one pair at most
            if folded and folded[-1] == i - 1:
                continue
            quad = np.concatenate([quads[i, :3], quads[i + 1, 2:3]])
            if planar_parts(quad, float(np.ptp(quad, axis=0).max()))[1] > 0.0:
                folded.append(i)
        folds = np.asarray(folded, dtype=np.int64)
        owner = np.delete(np.arange(n, dtype=np.int64), folds + 1)
        corners = 4 * owner[:, None] + np.arange(4)
        corners[np.searchsorted(owner, folds), 3] = 4 * folds + 6
        sizes = np.where(is_triangle[owner] & ~np.isin(owner, folds), 3, 4).tolist()
        return [row[:k] for row, k in zip(corners, sizes)], owner


def _check_materials(rho: np.ndarray, emission: np.ndarray, where: str) -> None:
    if not np.isfinite(rho).all() or (rho < 0).any() or (rho >= 1).any():
        raise SceneError(f"{where}: reflectance must be in [0, 1) per channel")
    if not np.isfinite(emission).all() or (emission < 0).any():
        raise SceneError(f"{where}: emission must be finite and non-negative")


def load_scene(path, *, max_patch_size: float | None = None, emission: str = "radiance", **options) -> Scene:
    """Load an OBJ + MTL scene and cut it into patches.

    Parameters
    ----------
    path : str or Path
        The OBJ file; ``mtllib`` files are read relative to it.
    max_patch_size : float, optional
        Longest patch edge in metres (after unit conversion). None keeps each face whole
        (non-planar or non-convex faces are split into triangles).
    emission : {"radiance", "exitance"}, default: "radiance"
        How to read ``Ke``: as emitted radiance L (E = pi L, what renderers do) or as exitance E.
    units : {"m", "cm", "mm"}, optional
        Units of the file's coordinates. Not given: metres, with a warning if the scene is
        more than 50 m across (a millimetre file read as metres); give "m" to silence it.
    allow_clamp : bool, default: False
        Clamp reflectances >= 1 to 0.999 (with a warning) instead of refusing the scene.
    imprint : bool, default: True
        Cut faces along the outlines of other objects touching them (a block's footprint on
        the floor, a light under the ceiling) and flag the covered regions in
        ``Scene.patch_hidden``; see :mod:`radiosity.imprint` and ``docs/meshing.md``.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        Unreadable or malformed files, unknown materials, bad reflectance or emission; the
        message names the file and line.

    Examples
    --------
    >>> import radiosity
    >>> scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    >>> scene.objects[:3]
    ['floor', 'ceiling', 'back_wall']
    """
    if "two_sided" in options:  # was accepted and ignored: refuse it rather than pretend
        raise TypeError("load_scene option 'two_sided' is not supported: surfaces are one-sided; model a "
                        "two-sided sheet as two faces back to back (opposite windings)")
    reject_unknown(options, LOAD_OPTIONS, "load_scene option")
    if Path(path).suffix.lower() == ".vs3":
        return load_vs3(path, max_patch_size=max_patch_size)
    if emission not in EMISSION_MODES:
        raise ValueError(f"emission must be one of {EMISSION_MODES}, got {emission!r}")
    units = options.get("units")  # None: metres, and the millimetre heuristic may warn
    if units is not None and units not in UNITS:
        raise ValueError(f"units must be one of {tuple(UNITS)}, got {units!r}")
    if max_patch_size is not None and not (np.isfinite(max_patch_size) and max_patch_size > 0):
        raise ValueError(f"max_patch_size must be a positive number of metres, got {max_patch_size!r}")
    data = read_obj(path)
    vertices = data.vertices * UNITS[units or "m"]
    keep, duplicate_notes = duplicate_faces(data.path, data.vertices, data.faces, data.face_line,
                                            data.face_object, data.objects)
    kept = np.flatnonzero(keep)
    faces = data.faces if len(kept) == len(data.faces) else [data.faces[k] for k in kept]
    _memory.check_patches(vertices, faces, max_patch_size)  # refuse before cutting, not during
    uncut = True  # no face was imprinted: with max_patch_size None the patches are the light paths' faces
    crossing_notes: list[str] = []
    if options.get("imprint", True):
        patches, report, cut = subdivide_imprinted(vertices, faces, data.face_object[kept], max_patch_size)
        uncut = cut.uncut
        crossing_notes = _crossing_notes(data, kept, cut.crossings)
    else:
        patches, report = subdivide_faces(vertices, faces, max_patch_size)
    patches, report = _in_file_faces(patches, report, kept)
    notes = (list(data.warnings) + _units_notes(data, units) + duplicate_notes + _face_notes(data, report)
             + crossing_notes + material_notes(data.materials))
    if patches.n_patches == 0:
        for note in notes:
            warnings.warn(note, RadiosityWarning, stacklevel=2)
        msg = (f"{data.path}: all {len(data.faces)} face(s) have zero area (degenerate); nothing to solve")
        raise SceneError(msg)
    rho, em = _patch_materials(data, patches, emission, options.get("allow_clamp", False), notes)
    if not em.any():
        notes.append(f"{data.path}: no face emits light (no material used has Ke > 0); "
                     "the solution is all zero")
    paths = _emitter_paths(data, vertices, faces, kept, emission,
                           patches if uncut and max_patch_size is None else None, hidden_from=patches)
    notes += light_path_notes(paths, str(data.path))
    for note in notes:
        if MEASURED not in note:  # the package's own measured data is no surprise to warn about
            warnings.warn(note, RadiosityWarning, stacklevel=2)
    return Scene(
        objects=data.objects,
        patch_quads=patches.quads,
        patch_object=data.face_object[patches.patch_face],
        patch_face=patches.patch_face,
        reflectance=rho,
        emission=em,
        max_patch_size=max_patch_size,
        source=str(data.path),
        face_line=data.face_line,
        notes=tuple(notes),
        patch_hidden=patches.patch_hidden,
        emission_mode=emission,
        light_paths=paths.as_dict() if paths is not None else None,
    )


def _emitter_paths(data, vertices: np.ndarray, faces: list[np.ndarray], kept: np.ndarray, emission: str,
                   coarse: Patches | None = None, hidden_from: Patches | None = None):
    """Where the emitters' light first lands (``_lightpaths``), traced on the faces as written
    (one patch per face, no imprint): the cost does not grow with ``max_patch_size``.
    ``coarse``: those patches if the caller has them (faces uncut, no size limit).
    ``hidden_from``: the scene's patches; a face emits only from its part no contact hides (a
    lamp's top flush with the ceiling sent its rays through the ceiling's plane: "48% escape"
    from a closed room whose energy balance lost 0.2%)."""
    if coarse is None:
        coarse, report = subdivide_faces(vertices, faces, None)
        coarse, _ = _in_file_faces(coarse, report, kept)
    if coarse.n_patches == 0:
        return None
    ke = np.array([m.ke for m in data.materials] + [(0.0, 0.0, 0.0)], dtype=float).reshape(-1, 3)
    em = (np.pi if emission == "radiance" else 1.0) * ke[data.face_material[coarse.patch_face]]
    if hidden_from is not None and hidden_from.patch_hidden.any():
        em = em * _unhidden_share(hidden_from, len(data.faces))[coarse.patch_face, None]
    quads = coarse.quads
    # Rays start on emitting patches only (and on the last patch, where a draw rounded past the
    # power's total would land): areas and normals elsewhere are never read, and cost seconds
    # on 10^5 faces. Each row's numbers are those of the whole arrays.
    rows = np.union1d(np.flatnonzero(em.sum(axis=1) > 0), [len(quads) - 1])
    area, normals = np.zeros(len(quads)), np.zeros((len(quads), 3))
    area[rows] = centroids_and_areas(quads[rows])[1]
    normals[rows] = polygon_normals(quads[rows])
    scale = float(np.linalg.norm(np.ptp(quads.reshape(-1, 3), axis=0)))
    return trace_emitters(quads, normals, em, area, data.face_object[coarse.patch_face], data.objects, scale)


def _unhidden_share(patches: Patches, n_faces: int) -> np.ndarray:
    """(n_faces,) share of each face's area that no contact hides (1 for faces with no hidden part)."""
    share = np.ones(n_faces)
    faces = np.unique(patches.patch_face[patches.patch_hidden])
    rows = np.flatnonzero(np.isin(patches.patch_face, faces))
    area = centroids_and_areas(patches.quads[rows])[1]
    face = patches.patch_face[rows]
    total = np.bincount(face, area, minlength=n_faces)[faces]
    hidden = np.bincount(face, np.where(patches.patch_hidden[rows], area, 0.0), minlength=n_faces)[faces]
    share[faces] = np.clip(1.0 - hidden / np.where(total > 0, total, 1.0), 0.0, 1.0)
    return share


def _crossing_notes(data, kept: np.ndarray, crossings: list[tuple[int, int]]) -> list[str]:
    """One note naming the faces of different objects that pass through each other (imprinting
    cuts along contacts only), or none."""
    if not crossings:
        return []

    def named(face: int) -> str:
        k = kept[face]
        return f"line {data.face_line[k]} ({data.objects[data.face_object[k]]})"

    shown = _named([f"{named(a)} and {named(b)}" for a, b in crossings])
    return [f"{data.path}: faces of different objects pass through each other: {shown}; they are not "
            "cut where they cross, so the patches there average the light of both sides (a box sunk 5 cm "
            "into a floor left floor patches 0.2 m away 2.3% short in a furnace test); let objects touch, "
            "not overlap"]


def _in_file_faces(patches: Patches, report: FaceReport, kept: np.ndarray) -> tuple[Patches, FaceReport]:
    """Patches and face report with face indices of the file (``kept[i]`` is file face of face i)."""
    if len(kept) and kept[-1] == len(kept) - 1:
        return patches, report  # nothing was dropped
    report = FaceReport([int(kept[f]) for f in report.degenerate], [(int(kept[f]), d) for f, d in report.nonplanar])
    return replace(patches, patch_face=kept[patches.patch_face]), report


# A scene larger than this (file units, no units given) is probably in millimetres or centimetres.
_MM_HINT_EXTENT = 50.0
# At most this many faces are named one by one in a note; the rest are counted.
_NOTE_FACES = 5


def _units_notes(data, units: str | None) -> list[str]:
    """A note when no units were given and the scene looks like millimetres (over 50 m across)."""
    if units is not None or not data.faces:
        return []
    used = used_vertices(data.faces, len(data.vertices))
    extent = float(np.ptp(data.vertices[used], axis=0).max())
    if extent <= _MM_HINT_EXTENT:
        return []
    return [f"{data.path}: the scene is {extent:.4g} m across (more than {_MM_HINT_EXTENT:g} m); if its "
            f"coordinates are millimetres, give units='mm' (--units mm); units='m' (--units m) keeps metres "
            "without this note"]


# How a note on a bundled scene's non-planar face ends: the data are measurements, kept as published.
MEASURED = "this is the measured geometry, kept as published"


def _is_bundled(path) -> bool:
    """Whether ``path`` is one of the scenes shipped with the package (``meshes/``)."""
    try:
        return Path(path).resolve().parent == bundled_scene(Path(path).stem).resolve().parent
    except (SceneError, OSError):
        return False


def _face_notes(data, report) -> list[str]:
    """Notes on non-planar faces (split) and zero-area faces (dropped), a few named, the rest counted."""
    notes = []
    measured = f"; {MEASURED}" if _is_bundled(data.path) else ""
    for face, deviation in report.nonplanar[:_NOTE_FACES]:
        notes.append(f"{data.path}:{data.face_line[face]}: face {face + 1} is not planar "
                     f"(off by {deviation:.3g} m); split into triangles from its first vertex" + measured)
    if len(report.nonplanar) > _NOTE_FACES:
        notes.append(f"{data.path}: {len(report.nonplanar) - _NOTE_FACES} more non-planar face(s) split "
                     f"(largest deviation {max(d for _, d in report.nonplanar):.3g} m)")
    for face in report.degenerate[:_NOTE_FACES]:
        notes.append(f"{data.path}:{data.face_line[face]}: face {face + 1} has zero area; ignored")
    if len(report.degenerate) > _NOTE_FACES:
        notes.append(f"{data.path}: {len(report.degenerate) - _NOTE_FACES} more zero-area face(s) ignored")
    return notes


def _patch_materials(data, patches: Patches, emission: str, allow_clamp: bool, notes: list | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    n_mat = len(data.materials)
    kd = np.array([m.kd for m in data.materials] + [(0.0, 0.0, 0.0)], dtype=float).reshape(n_mat + 1, 3)
    ke = np.array([m.ke for m in data.materials] + [(0.0, 0.0, 0.0)], dtype=float).reshape(n_mat + 1, 3)
    for m in data.materials:
        kd_text = " ".join(f"{v:g}" for v in m.kd)
        kd_where, ke_where = m.kd_where or m.where, m.ke_where or m.where
        if min(m.kd) < 0:
            raise SceneError(f"{kd_where}: material {m.name!r} has Kd {kd_text}; reflectance must be in "
                             "[0, 1) per channel, and a negative one is never valid")
        if max(m.kd) >= 1 and not allow_clamp:
            raise SceneError(f"{kd_where}: material {m.name!r} has Kd {kd_text}; reflectance must be in "
                             "[0, 1) per channel (1 or more never converges); allow_clamp=True "
                             "(--allow-clamp) clamps it to 0.999")
        if max(m.kd) >= 1 and notes is not None:
            notes.append(f"{kd_where}: material {m.name!r} has Kd {kd_text}; clamped to 0.999 (allow_clamp)")
        if min(m.ke) < 0:
            raise SceneError(f"{ke_where}: material {m.name!r} has negative Ke "
                             f"{' '.join(f'{v:g}' for v in m.ke)}; emission must be >= 0")
    if allow_clamp and (kd >= 1).any():
        if notes is None:
            warnings.warn("reflectance >= 1 clamped to 0.999", RadiosityWarning, stacklevel=3)
        kd = np.minimum(kd, 0.999)
    scale = np.pi if emission == "radiance" else 1.0
    material = data.face_material[patches.patch_face]  # -1 (no material) picks the zero row
    return kd[material].copy(), scale * ke[material]


def load_vs3(path, *, max_patch_size: float | None = None) -> Scene:
    """A View3D ``.vs3`` model as a Scene, meant as View3D means it.

    - Every subsurface (``base`` column) is cut out of its base: the base keeps only the rest
      (its area shrinks by its subsurfaces', as View3D's post-processing does).
    - Surfaces joined by ``cmb`` are one object, named after the surface they join: the
      object sums of F (``ViewFactors.grouped("object")``) are View3D's output surfaces.
    - ``encl=1`` is kept in ``Scene.enclosure`` (``enforce="auto"`` then means closure);
      ``emit=1`` (Hottel's script-F) is refused with a note: F stays the black view factors.

    ``patch_face`` is the model's surface (0-based: surface ``n`` is ``n - 1``) each patch
    came from. Reflectance is ``1 - emissivity`` (grey body), nothing emits; obstructions block
    light but are left out of the view-factor matrix (their rows and columns are zero).
    """
    from .io.view3d import read_vs3, separate_and_combine

    model = read_vs3(path)
    cut = separate_and_combine(model)
    patches, report = subdivide_faces(cut.vertices, cut.faces, max_patch_size)
    if report.degenerate:
        bad = int(cut.face_surface[report.degenerate[0]])
        raise SceneError(f"{path}:{model.line[bad]}: surface {bad + 1} ({model.names[bad]}) has zero area")
    surface = cut.face_surface[patches.patch_face]
    emissivity = np.asarray(model.emissivity)
    rho = np.repeat((1.0 - emissivity[surface])[:, None], 3, axis=1)
    notes = list(model.notes) + cut.notes
    notes += [f"{path}:{model.line[cut.face_surface[f]]}: surface {cut.face_surface[f] + 1} is not planar "
              f"(off by {d:.3g} m); split into triangles" for f, d in report.nonplanar]
    if model.emittances:
        notes.append(f"{path}: emit=1 asks for Hottel's script-F (reflections included); radiosity "
                     "computes black view factors F and ignores it (the emissivities are kept as "
                     "reflectance 1 - emit for a grey-body solve)")
    for note in notes:
        warnings.warn(note, RadiosityWarning, stacklevel=3)
    return Scene(objects=list(cut.objects), patch_quads=patches.quads, patch_object=cut.surface_object[surface],
                 patch_face=surface, reflectance=np.clip(rho, 0.0, 0.999), emission=np.zeros((len(surface), 3)),
                 max_patch_size=max_patch_size, source=str(path), notes=tuple(notes),
                 patch_obstruction=np.asarray(model.obstruction)[surface], enclosure=model.enclosure)


def bundled_scene(name: str = "cornell_box") -> Path:
    """Path of a scene shipped with the package (``meshes/NAME.obj``)."""
    here = Path(__file__).resolve().parent
    for folder in (here.parent / "meshes", here / "meshes"):
        candidate = folder / f"{name}.obj"
        if candidate.exists():
            return candidate
    from importlib.resources import files

    try:  # installed: the meshes are the package radiosity.meshes
        candidate = Path(str(files("radiosity.meshes") / f"{name}.obj"))
    except ModuleNotFoundError:  # run from a source tree, where meshes/ sits beside the package
        candidate = None
    if candidate is not None and candidate.exists():
        return candidate
    raise SceneError(f"no bundled scene named {name!r}")
