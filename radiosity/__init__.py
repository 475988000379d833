"""radiosity: diffuse global illumination and exact view factors on polygon meshes.

Public API
----------
point_to_polygon    -- form factor from differential receivers to a polygon (Lambert)
point_to_polygons   -- the same against many polygons at once: an (m, n) matrix
polygon_to_polygon  -- area-averaged form factor between two polygons, to a tolerance
load_scene          -- OBJ + MTL scene cut into patches (Scene)
bundled_scene       -- path of a scene shipped with the package ("cornell_box", ...)
solve               -- radiosity solution of a scene (Solution), with presets
view_factors        -- sparse patch-to-patch view-factor matrix with occlusion
compute_view_factors -- the same with the patches it belongs to, sky factors, sums (ViewFactors)
write_view_factors  -- the same written out of core, block by block, into a shard folder
load_view_factors   -- a matrix written out of core, read lazily (shape, rows, F @ x, solve)
exchange            -- grey-body radiative exchange (net radiation method): Exchange
Scene, Solution, Exchange, Options, PRESETS, ViewFactors
RadiosityError, SceneError, MemoryBudgetError, RadiosityWarning
__version__         -- the installed package's version (from its metadata)
"""

from ._startup import guard_imports  # first: a signal from here on ends with one line

with guard_imports():  # Ctrl-C during these seconds of imports: one line and exit 130
    from importlib.metadata import PackageNotFoundError as _NotInstalled
    from importlib.metadata import version as _version

    from ._errors import MemoryBudgetError, RadiosityError, RadiosityWarning, SceneError
    from .exchange import Exchange, exchange
    from .factors import ViewFactors
    from .formfactors import point_to_polygon, point_to_polygons, polygon_to_polygon
    from .options import PRESETS, Options
    from .scene import Scene, bundled_scene, load_scene
    from .solution import Solution
    from .methods.uniform.shards import load_view_factors
    from .solve import compute_view_factors, solve, view_factors, write_view_factors

try:
    __version__ = _version("radiosity")
except _NotInstalled:  # pragma: no cover - run from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = [
    "point_to_polygon",
    "point_to_polygons",
    "polygon_to_polygon",
    "load_scene",
    "bundled_scene",
    "solve",
    "view_factors",
    "compute_view_factors",
    "write_view_factors",
    "load_view_factors",
    "ViewFactors",
    "exchange",
    "Exchange",
    "Scene",
    "Solution",
    "Options",
    "PRESETS",
    "RadiosityError",
    "SceneError",
    "MemoryBudgetError",
    "RadiosityWarning",
]
