"""Grey-body radiative exchange between a scene's patches: the net radiation method.

Every patch is a diffuse grey surface with an emissivity ``eps`` and exactly one prescribed
condition: a temperature ``T`` (K) or a net heat flux ``q`` (W/m^2, leaving the surface). With
radiosity ``J`` (W/m^2 leaving) and irradiance ``H = sum_j F_ij J_j + F_i,amb sigma T_amb^4``::

    prescribed T:   J_i - (1 - eps_i) sum_j F_ij J_j = eps_i sigma T_i^4 + (1 - eps_i) F_i,amb sigma T_amb^4
    prescribed q:   J_i -             sum_j F_ij J_j = q_i               +             F_i,amb sigma T_amb^4

one sparse linear system for all patches, whatever mix of conditions. Then ``q_i = J_i - H_i``
and, where q was given, ``sigma T_i^4 = J_i + (1 - eps_i) q_i / eps_i``. An open scene sends the
part ``F_i,amb = 1 - sum_j F_ij`` of each row to a black ambient (sky) node at ``ambient`` K.
See ``docs/exchange.md``.
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Union

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import _memory
from ._errors import RadiosityError, RadiosityWarning, SceneError
from .enclosure import enforce_reciprocity
from .scene import Scene

__all__ = ["Exchange", "exchange", "STEFAN_BOLTZMANN"]

# Stefan-Boltzmann constant, W/(m^2 K^4) (CODATA 2018; exact given the SI defining constants).
STEFAN_BOLTZMANN = 5.670374419e-8

# A row of F may fall short of (or exceed) 1 by this much and still count as closed: the
# quadrature and visibility error of a fill (view_factors is ~1e-6 per factor; View3D's float32
# output ~1e-7; a hemicube ~1e-3 would need an ambient or enforce="closure" explicitly).
CLOSURE_TOL = 1e-4

# Relative residual the linear solve must reach; looser means a singular or ill-posed system.
SOLVE_RTOL = 1e-10

# Below this many unknowns a sparse LU is cheaper than a Krylov solve (as in system.py).
DIRECT_MAX = 1500

ENFORCE_MODES = ("auto", "none", "reciprocity", "closure")

# A condition: one value for every patch, {object name: value}, or one value per patch.
Condition = Union[float, Mapping[str, float], np.ndarray]


@dataclass(frozen=True, eq=False)
class Exchange:
    """The solved grey-body exchange of a scene.

    Attributes
    ----------
    scene : Scene
        The scene, with the patches the conditions apply to.
    F : scipy.sparse.csr_matrix
        The view-factor matrix used (after enforcement), ``F[i, j] = F(i -> j)``.
    emissivity : (n_patches,) float
        Emissivity per patch, in (0, 1].
    temperature : (n_patches,) float
        Temperature per patch, K: prescribed or solved for.
    net_flux : (n_patches,) float
        Net radiative heat flux leaving each patch, W/m^2 (emitted minus absorbed).
    radiosity : (n_patches,) float
        Radiosity J (emitted plus reflected), W/m^2.
    irradiance : (n_patches,) float
        Irradiance H arriving at each patch's front, W/m^2 (``net_flux = J - H``).
    ambient_factor : (n_patches,) float
        ``F_i,amb``: the part of each patch's radiation that reaches the ambient node
        (``1 - sum_j F_ij`` with an ambient; zeros without one).
    ambient : float or None
        Ambient (sky) temperature, K, or None for a closed scene.
    prescribed : (n_patches,) str
        ``"T"`` where the temperature was prescribed, ``"q"`` where the heat flux was, ``""``
        for patches outside the exchange (obstructions, hidden patches).
    active : (n_patches,) bool
        Patches taking part; the others (View3D obstructions, patches covered by a contact)
        have zero net flux and radiosity, and their prescribed temperature (0 K if none).
    """

    scene: Scene
    F: sp.csr_matrix
    emissivity: np.ndarray
    temperature: np.ndarray
    net_flux: np.ndarray
    radiosity: np.ndarray
    irradiance: np.ndarray
    ambient_factor: np.ndarray
    ambient: float | None
    prescribed: np.ndarray
    active: np.ndarray

    @property
    def net_power(self) -> np.ndarray:
        """(n_patches,) net radiative power leaving each patch, W."""
        return self.net_flux * self.scene.patch_area

    @cached_property
    def ambient_net_power(self) -> float:
        """Net power leaving the ambient node, W: ``sum_i A_i F_i,amb (sigma T_amb^4 - J_i)``."""
        if self.ambient is None:
            return 0.0
        eb = STEFAN_BOLTZMANN * self.ambient**4
        return float((self.scene.patch_area * self.ambient_factor * (eb - self.radiosity)).sum())

    def _per_object(self, values: np.ndarray, weights: np.ndarray | None) -> dict[str, float]:
        from .solution import patch_groups

        groups = patch_groups(self.scene.patch_object)
        out = {}
        for index, name in enumerate(self.scene.objects):
            mask = groups.get(index, np.zeros(0, np.int64))
            if weights is None:
                out[name] = float(values[mask].sum())
            else:
                total = weights[mask].sum()
                out[name] = float((weights[mask] * values[mask]).sum() / total) if total > 0 else 0.0
        return out

    def object_net_power(self) -> dict[str, float]:
        """Net radiative power leaving each named object, W (positive: it loses heat)."""
        return self._per_object(self.net_power, None)

    def object_net_flux(self) -> dict[str, float]:
        """Area-weighted mean net flux leaving each named object, W/m^2."""
        return self._per_object(self.net_flux, self.scene.patch_area)

    def object_temperature(self) -> dict[str, float]:
        """Area-weighted mean temperature of each named object, K."""
        return self._per_object(self.temperature, self.scene.patch_area)

    def object_emissivity(self) -> dict[str, float]:
        """Area-weighted mean emissivity of each named object."""
        return self._per_object(self.emissivity, self.scene.patch_area)

    def energy_balance(self) -> dict[str, float]:
        """Energy check: the net powers of the surfaces and of the ambient sum to zero.

        Returns
        -------
        dict
            ``surfaces_W`` (sum of the patches' net powers), ``ambient_W`` (net power leaving
            the ambient node), ``residual_W`` (their sum) and ``relative`` (the residual over
            the largest power involved). With reciprocity enforced (the default), ``relative``
            is the linear solve's residual, 1e-16 to 1e-13 in the tests.
        """
        power = self.net_power[self.active]
        surfaces = float(power.sum())
        residual = surfaces + self.ambient_net_power
        scale = max(float(np.abs(power).sum()) + abs(self.ambient_net_power), 1e-300)
        return {"surfaces_W": surfaces, "ambient_W": self.ambient_net_power, "residual_W": residual,
                "relative": abs(residual) / scale}


class OpenSceneError(SceneError):
    """Rows of F fall short of 1 and no ambient takes the rest: about the scene and its matrix,
    not the conditions."""


def exchange(scene: Scene, *, emissivity: Condition, temperature: Condition | None = None,
             heat_flux: Condition | None = None, ambient: float | None = None,
             view_factors: sp.spmatrix | np.ndarray | None = None, enforce: str = "auto", **options) -> Exchange:
    """Grey-body radiative exchange between the scene's patches (net radiation method).

    Parameters
    ----------
    scene : Scene
        From :func:`load_scene`; the conditions apply to its patches as loaded.
    emissivity : float, dict or (n_patches,) array
        Hemispherical emissivity in (0, 1]: one value for all, ``{object name: value}`` (every
        object taking part must be named) or one value per patch.
    temperature : dict or (n_patches,) array, optional
        Prescribed temperatures, K (>= 0): ``{object name: T}`` or per patch, NaN where the
        heat flux is prescribed instead. A scalar prescribes every patch.
    heat_flux : dict or (n_patches,) array, optional
        Prescribed net radiative flux leaving the surface, W/m^2 (negative: it absorbs), in
        the same forms. Every patch needs exactly one of ``temperature`` and ``heat_flux``.
    ambient : float, optional
        Temperature of a black ambient (sky) node, K, that receives the part of each row
        missing from F (``1 - sum_j F_ij``). Required if the scene is open.
    view_factors : (n_patches, n_patches) sparse matrix or array, optional
        ``F[i, j] = F(i -> j)``; default: ``radiosity.view_factors(scene, **options)``.
    enforce : {"auto", "none", "reciprocity", "closure"}, default: "auto"
        How F is made consistent before use (:func:`radiosity.enclosure.enforce_reciprocity`):
        "auto" enforces reciprocity, and closure too when there is no ambient, so energy is
        conserved to the solver's precision. "none" uses F as given. "closure" asserts the
        scene is closed: rows short of 1 by more than ``CLOSURE_TOL`` are scaled up instead of
        refused (with no ambient), and rows above ``1 + CLOSURE_TOL`` (refused otherwise) are
        scaled down, with a warning naming the worst.
    **options
        Passed to :func:`radiosity.view_factors` when ``view_factors`` is None (``preset``,
        ``cache``, ``formfactor_rtol``, ...); ``max_patch_size`` is refused (load the scene
        with it, so that the conditions and the matrix share the patches).

    Returns
    -------
    Exchange

    Raises
    ------
    ValueError
        A condition missing, given twice or out of range, an unknown object name (the message
        names them), a matrix of the wrong shape.
    SceneError
        An open scene (rows of F short of 1 by more than ``CLOSURE_TOL``) without ``ambient``.
    RadiosityError
        An ill-posed system: only heat fluxes and no ambient, or a flux no temperature can meet.
    TypeError
        An unknown ``enforce``, ``max_patch_size`` in ``options``, or ``options`` together
        with ``view_factors``.

    Notes
    -----
    The two rows of the system, with ``E_b = sigma T^4`` and ``H_i = sum_j F_ij J_j + F_i,amb
    E_b,amb``, are ``J_i = eps_i E_b,i + (1 - eps_i) H_i`` (prescribed T) and ``J_i - H_i = q_i``
    (prescribed q); see ``docs/exchange.md``. The energy check ``sum_i A_i q_i + P_amb = 0``
    holds exactly when ``A_i F_ij = A_j F_ji``, hence the default enforcement.

    Examples
    --------
    A closed unit cube, one face hot and the others cold, all black: the hot face loses
    ``sigma (T_hot^4 - T_cold^4)`` per square metre, since it sees only cold faces.

    >>> import radiosity
    >>> scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    >>> T = {name: 300.0 for name in scene.objects} | {"top": 600.0}
    >>> ex = radiosity.exchange(scene, emissivity=1.0, temperature=T, cache=False)
    >>> round(ex.object_net_power()["top"], 3), round(5.670374419e-8 * (600**4 - 300**4), 3)
    (6889.505, 6889.505)
    >>> ex.energy_balance()["relative"] < 1e-12
    True
    """
    if enforce not in ENFORCE_MODES:
        raise TypeError(f"unknown enforce {enforce!r}; valid: {', '.join(ENFORCE_MODES)}")
    active = _active(scene)
    _note_inactive(scene, active)
    eps, T, q = _conditions(scene, active, emissivity, temperature, heat_flux)
    ambient = _ambient(ambient)
    F = _matrix(scene, view_factors, options)
    idx = np.flatnonzero(active)
    Fa = F if len(idx) == scene.n_patches else F[idx][:, idx].tocsr()
    Fa, f_amb = _closed(Fa, scene, idx, ambient, enforce)
    has_T = ~np.isnan(T[idx])
    J = _solve(Fa, eps[idx], T[idx], q[idx], has_T, f_amb, ambient)
    return _result(scene, F, Fa, idx, eps, T, q, has_T, J, f_amb, ambient, active)


# --- validation ---------------------------------------------------------------------------

def _active(scene: Scene) -> np.ndarray:
    """Patches taking part: not View3D obstructions, not covered by a contact (as solve does)."""
    return ~scene.patch_inactive


def _note_inactive(scene: Scene, active: np.ndarray) -> None:
    """Warn that some patches take no part: an exchange that silently drops surfaces misleads."""
    if active.all():
        return
    names = [scene.objects[k] for k in np.unique(scene.patch_object[~active])]
    msg = (f"{int((~active).sum())} patch(es) of object(s) {', '.join(map(repr, names))} take no part in the "
           "exchange (View3D obstructions, or covered by another object within the contact tolerance; "
           "load_scene(..., imprint=False) keeps close surfaces apart); their net flux is 0")
    warnings.warn(msg, RadiosityWarning, stacklevel=3)


def _is_number(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _per_patch(value, name: str, scene: Scene) -> tuple[np.ndarray, bool]:
    """``value`` spread over the patches (NaN where not given); and whether it came per object."""
    n = scene.n_patches
    if value is None:
        return np.full(n, np.nan), True
    if _is_number(value) or (isinstance(value, np.ndarray) and value.ndim == 0):
        return np.full(n, float(value)), True
    if isinstance(value, Mapping):
        unknown = [k for k in value if k not in scene.objects]
        if unknown:
            msg = (f"{name}: unknown object(s) {', '.join(map(repr, unknown))}; "
                   f"the scene's objects: {', '.join(scene.objects)}")
            raise ValueError(msg)
        per_object = np.full(len(scene.objects), np.nan)
        for key, v in value.items():
            if not _is_number(v):
                raise ValueError(f"{name} of object {key!r} must be a number, got {v!r}")
            per_object[scene.objects.index(key)] = float(v)
        return per_object[scene.patch_object], True
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, a dict {{object name: value}} or an array of "
                         f"shape (n_patches,) = ({n},), got {type(value).__name__}") from None
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a dict {{object name: value}} or an array of shape "
                         f"(n_patches,) = ({n},), got shape {arr.shape}")
    return arr.copy(), False


def _where(scene: Scene, bad: np.ndarray, by_object: bool) -> str:
    """Name the first offending patch(es): by object, or by patch index and object."""
    i = int(np.flatnonzero(bad)[0])
    obj = scene.objects[scene.patch_object[i]]
    if by_object:
        names = sorted({scene.objects[k] for k in scene.patch_object[bad]}, key=scene.objects.index)
        return "object(s) " + ", ".join(map(repr, names))
    more = f" and {int(bad.sum()) - 1} more" if bad.sum() > 1 else ""
    return f"patch {i} (object {obj!r}){more}"


def _conditions(scene, active, emissivity, temperature, heat_flux):
    """Per-patch emissivity, temperature and heat flux (NaN where not given), validated."""
    eps, eps_obj = _per_patch(emissivity, "emissivity", scene)
    T, T_obj = _per_patch(temperature, "temperature", scene)
    q, q_obj = _per_patch(heat_flux, "heat_flux", scene)
    missing = active & np.isnan(eps)
    if missing.any():
        raise ValueError(f"no emissivity for {_where(scene, missing, eps_obj)}")
    bad = active & ~((eps > 0) & (eps <= 1))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"emissivity of {_where(scene, bad, eps_obj)} must be in (0, 1], got {eps[i]!r}")
    bad = ~np.isnan(T) & ~(np.isfinite(T) & (T >= 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"temperature of {_where(scene, bad, T_obj)} must be finite and >= 0 K, got {T[i]!r}")
    bad = ~np.isnan(q) & ~np.isfinite(q)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"heat_flux of {_where(scene, bad, q_obj)} must be finite, got {q[i]!r}")
    both = active & ~np.isnan(T) & ~np.isnan(q)
    if both.any():
        raise ValueError(f"{_where(scene, both, T_obj and q_obj)} has both a temperature and a heat_flux; "
                         "give exactly one")
    neither = active & np.isnan(T) & np.isnan(q)
    if neither.any():
        raise ValueError(f"no temperature or heat_flux for {_where(scene, neither, T_obj and q_obj)}; "
                         "every surface needs exactly one")
    return np.nan_to_num(eps, nan=1.0), T, q


def _ambient(ambient) -> float | None:
    if ambient is None:
        return None
    if not _is_number(ambient) or not (np.isfinite(ambient) and ambient >= 0):
        raise ValueError(f"ambient must be a temperature in K (finite, >= 0), got {ambient!r}")
    return float(ambient)


def _matrix(scene: Scene, view_factors, options: dict) -> sp.csr_matrix:
    """The given view-factor matrix, checked, or the scene's own computed as loaded."""
    n = scene.n_patches
    if view_factors is None:
        if "max_patch_size" in options:
            raise TypeError("exchange: max_patch_size would cut the patches again, away from the "
                            "conditions; load the scene with load_scene(path, max_patch_size=...)")
        from .solve import view_factors as compute

        F = compute(scene, **options)
    else:
        if options:
            raise TypeError(f"exchange: options {', '.join(map(repr, sorted(options)))} only apply when "
                            "view_factors is None (it is computed here)")
        F = view_factors
    F = sp.csr_matrix(F, dtype=float)
    if F.shape != (n, n):
        msg = (f"view_factors has shape {F.shape} but the scene has {n} patches; compute it with "
               "radiosity.view_factors(scene) on the scene as loaded")
        raise ValueError(msg)
    if not np.isfinite(F.data).all() or (F.data < 0).any():
        raise ValueError("view_factors must be finite and non-negative")
    return F


def _closed(Fa: sp.csr_matrix, scene: Scene, idx: np.ndarray, ambient: float | None, enforce: str):
    """F made consistent (reciprocity, closure) and each row's ambient factor; refuse open scenes."""
    area = scene.patch_area[idx]
    rows = np.asarray(Fa.sum(axis=1)).ravel()
    short = 1.0 - rows
    # enforce="closure" asserts a closed enclosure whose fill fell short (e.g. ray visibility).
    if ambient is None and enforce != "closure" and (short > CLOSURE_TOL).any():
        worst = int(np.argmax(short))
        i = int(idx[worst])
        msg = (f"the scene is open: patch {i} (object {scene.objects[scene.patch_object[i]]!r}) sends "
               f"{short[worst]:.3g} of its radiation to no patch (row sum of F {rows[worst]:.6g}; "
               f"{int((short > CLOSURE_TOL).sum())} patch(es) short of 1 by more than {CLOSURE_TOL:g}); "
               "give an ambient temperature (K) for the surroundings they see; if the scene is "
               "closed and that is the matrix's error, compute it tighter or pass enforce='closure'")
        raise OpenSceneError(msg)
    if (short < -CLOSURE_TOL).any():
        worst = int(np.argmin(short))
        i = int(idx[worst])
        where = f"view factors of patch {i} (object {scene.objects[scene.patch_object[i]]!r}) sum to {rows[worst]:.6g}"
        if enforce != "closure":
            raise ValueError(f"{where} > 1: the matrix is not accurate enough for an exchange; "
                             'enforce="closure" scales such rows to 1 if the scene is closed')
        # Asked for explicitly: the user vouches that the enclosure is closed, so a row above 1
        # is fill error like a row below it, and closure scales both to 1.
        warnings.warn(f"exchange: {where}; scaled to 1 with the other rows (enforce='closure')",
                      RadiosityWarning, stacklevel=3)
    if enforce == "auto":
        enforce = "reciprocity" if ambient is not None else "closure"
    if enforce != "none" and Fa.shape[0] > 0:
        Fa = enforce_reciprocity(Fa, area, closure=enforce == "closure")
    if ambient is None:
        return Fa, np.zeros(len(idx))
    return Fa, 1.0 - np.asarray(Fa.sum(axis=1)).ravel()


# --- the system -----------------------------------------------------------------------------

def _solve(Fa, eps, T, q, has_T, f_amb, ambient) -> np.ndarray:
    """Radiosities J of the active patches from the mixed T/q system."""
    n = Fa.shape[0]
    if n == 0:
        return np.zeros(0)
    if not has_T.any() and ambient is None:
        raise RadiosityError("every surface has a prescribed heat_flux and there is no ambient: the "
                             "temperatures are then undetermined; prescribe at least one temperature "
                             "(or give an ambient)")
    eb_amb = STEFAN_BOLTZMANN * ambient**4 if ambient is not None else 0.0
    reflect = np.where(has_T, 1.0 - eps, 1.0)
    A = (sp.identity(n, format="csr") - sp.diags(reflect) @ Fa).tocsr()
    b = np.where(has_T, eps * STEFAN_BOLTZMANN * np.nan_to_num(T) ** 4, np.nan_to_num(q)) + reflect * f_amb * eb_amb
    J = _linear_solve(A, b)
    norm = max(np.linalg.norm(b), 1e-300)
    residual = np.linalg.norm(A @ J - b) / norm if np.isfinite(J).all() else np.inf
    if not residual <= SOLVE_RTOL * 1e3:
        msg = (f"the exchange system has no unique solution (relative residual {residual:.2g}): some group "
               "of surfaces has only prescribed heat fluxes and sees neither a prescribed temperature nor "
               "the ambient")
        raise RadiosityError(msg)
    return J


def _linear_solve(A: sp.csr_matrix, b: np.ndarray) -> np.ndarray:
    n = A.shape[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error", spla.MatrixRankWarning)
        try:
            if n > DIRECT_MAX:
                x, info = spla.gmres(A, b, x0=b.copy(), rtol=SOLVE_RTOL, atol=0.0, restart=100, maxiter=50)
                if info == 0:
                    return x
            _memory.check_solve(n, A.nnz, "direct")
            return np.atleast_1d(spla.spsolve(A.tocsc(), b))
        except spla.MatrixRankWarning:
            return np.full(n, np.nan)


def _result(scene, F, Fa, idx, eps, T, q, has_T, J, f_amb, ambient, active) -> Exchange:
    n = scene.n_patches
    eb_amb = STEFAN_BOLTZMANN * ambient**4 if ambient is not None else 0.0
    H = Fa @ J + f_amb * eb_amb
    flux = np.where(has_T, J - H, q[idx])
    eb = np.where(has_T, STEFAN_BOLTZMANN * np.nan_to_num(T[idx]) ** 4, J + (1.0 - eps[idx]) * flux / eps[idx])
    _check_reachable(eb, J, H, has_T, scene, idx)
    out = {name: np.zeros(n) for name in ("net_flux", "radiosity", "irradiance", "ambient_factor")}
    out["net_flux"][idx], out["radiosity"][idx], out["irradiance"][idx], out["ambient_factor"][idx] = flux, J, H, f_amb
    temperature = np.nan_to_num(T, nan=0.0)
    temperature[idx] = (np.maximum(eb, 0.0) / STEFAN_BOLTZMANN) ** 0.25
    prescribed = np.full(n, "", dtype="<U1")
    prescribed[idx] = np.where(has_T, "T", "q")
    F_used = sp.csr_matrix((n, n))
    if len(idx):
        embed = sp.csr_matrix((np.ones(len(idx)), (idx, np.arange(len(idx)))), shape=(n, len(idx)))
        F_used = (embed @ Fa @ embed.T).tocsr()
    return Exchange(scene=scene, F=F_used, emissivity=eps, temperature=temperature, ambient=ambient,
                    prescribed=prescribed, active=active, **out)


def _check_reachable(eb, J, H, has_T, scene, idx) -> None:
    """A prescribed flux that would need T^4 < 0 (absorbing more than arrives) is refused."""
    scale = max(float(np.abs(J).max(initial=0.0)), float(np.abs(H).max(initial=0.0)), 1e-300)
    bad = ~has_T & (eb < -1e-9 * scale)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        i = int(idx[k])
        msg = (f"the heat_flux of patch {i} (object {scene.objects[scene.patch_object[i]]!r}) cannot be met: "
               f"it would have to absorb more than emissivity x irradiance ({H[k]:.6g} W/m^2 arrives); "
               "no temperature >= 0 K gives it")
        raise RadiosityError(msg)
