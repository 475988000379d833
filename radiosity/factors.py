"""View factors with the patches they belong to: sums back to objects and faces, sky factors.

:func:`radiosity.view_factors` returns the bare matrix. When the fill cuts the scene further
(``max_patch_size``), that matrix belongs to patches the caller never saw; a
:class:`ViewFactors` keeps the matrix and the scene it was filled on together, so the two
always agree (``F.shape == (scene.n_patches,) * 2``, checked on construction). From it:

- :attr:`ViewFactors.sky_factor`: ``1 - sum_j F_ij``, the fraction of each patch's emission that
  leaves the scene (escapes to the sky); 0 in a closed enclosure, up to the fill's error.
- :meth:`ViewFactors.grouped`: the matrix summed back to the input surfaces, by object (the
  OBJ's ``o``/``g``; View3D's output surfaces) or by face (an OBJ face; a View3D ``S`` line),

      F_IJ = sum_{i in I, j in J} A_i F_ij / A_I,      A_I = sum_{i in I} A_i,

  which is exact view-factor algebra: reciprocity and closure carry over to the sums.
  Inactive patches (obstructions, hidden regions) are left out of the sums and their areas.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from .scene import Scene

__all__ = ["ViewFactors", "SurfaceFactors", "group_factors", "GROUPINGS"]

GROUPINGS = ("object", "face")


@dataclass(frozen=True, eq=False)
class SurfaceFactors:
    """A view-factor matrix summed back to groups of patches (objects or input faces).

    Attributes
    ----------
    F : (m, m) scipy.sparse.csr_matrix
        F[I, J] = F(I -> J) between groups.
    area : (m,) float
        Active area of each group, m^2 (obstructions and hidden patches left out).
    names : list of str
        Name of each group.
    emissivity : (m,) float
        Area-weighted mean of ``1 - reflectance`` over the group (what View3D files carry).
    patch_group : (n_patches,) int
        Group of each patch, -1 for patches left out.
    by : {"object", "face"}
    """

    F: sp.csr_matrix
    area: np.ndarray
    names: list[str]
    emissivity: np.ndarray
    patch_group: np.ndarray
    by: str

    @cached_property
    def row_sums(self) -> np.ndarray:
        """(m,) sum_J F_IJ."""
        return np.asarray(self.F.sum(axis=1)).ravel()

    @property
    def sky_factor(self) -> np.ndarray:
        """(m,) ``1 - sum_J F_IJ``: the fraction of each group's emission that leaves the scene."""
        return 1.0 - self.row_sums


def group_factors(F: sp.spmatrix, area: np.ndarray, group: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """Sum F over groups of patches by exchange areas.

    Parameters
    ----------
    F : (n, n) sparse
        F[i, j] = F(i -> j).
    area : (n,) float
        Patch areas, m^2.
    group : (n,) int
        Group of each patch (0 .. m-1), or -1 to leave the patch out.

    Returns
    -------
    F_groups : (k, k) csr_matrix
        Between the groups that have area (``kept``), in increasing group order.
    area_groups : (k,) float
    kept : (k,) int
        The group numbers that were kept.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> F = sp.csr_matrix(np.array([[0, 0, 1.0], [0, 0, 1.0], [0.25, 0.25, 0.5]]))
    >>> Fg, A, kept = group_factors(F, np.array([1.0, 1.0, 4.0]), np.array([0, 0, 1]))
    >>> Fg.toarray().tolist(), A.tolist()
    ([[0.0, 1.0], [0.5, 0.5]], [2.0, 4.0])
    """
    group = np.asarray(group, dtype=np.int64)
    n = len(group)
    member = np.flatnonzero(group >= 0)
    n_groups = int(group.max()) + 1 if len(member) else 0
    S = sp.csr_matrix((np.ones(len(member)), (group[member], member)), shape=(n_groups, n))
    A = S @ np.asarray(area, float)
    kept = np.flatnonzero(A > 0)
    S = S[kept]
    G = (S @ sp.diags(np.asarray(area, float)) @ sp.csr_matrix(F) @ S.T).tocsr()
    return (sp.diags(1.0 / A[kept]) @ G).tocsr(), A[kept], kept


@dataclass(frozen=True, eq=False)
class ViewFactors:
    """A view-factor matrix and the patches it belongs to, consistent by construction.

    Attributes
    ----------
    F : (n, n) scipy.sparse.csr_matrix
        F[i, j] = F(i -> j), with occlusion; rows and columns of inactive patches are zero.
    scene : Scene
        The scene as filled (cut further than the input if ``max_patch_size`` asked for it):
        its ``patch_quads``, ``patch_area``, ``patch_object``, ``patch_face``,
        ``patch_hidden`` and ``patch_obstruction`` describe F's rows and columns.
    enforced : {"none", "reciprocity", "closure"}
        What was enforced on F.
    settings : dict
        Fill tolerances (``formfactor_rtol``, ``visibility_rtol``, the file key of ``visibility_atol``) and the preset.
    error : (n, n) scipy.sparse.csr_matrix or None
        Estimated absolute error of each entry (``compute_view_factors(..., error_estimate=True)``).
    """

    F: sp.csr_matrix
    scene: Scene
    enforced: str = "none"
    settings: dict = field(default_factory=dict)
    error: sp.csr_matrix | None = None

    def __post_init__(self):
        n = self.scene.n_patches
        for name, matrix in (("view-factor matrix", self.F), ("error estimate", self.error)):
            if matrix is not None and matrix.shape != (n, n):
                msg = f"{name} of shape {matrix.shape} does not belong to a scene of {n} patches"
                raise ValueError(msg)

    @property
    def active(self) -> np.ndarray:
        """(n,) bool: patches that exchange light (not obstructions, not hidden)."""
        return ~(self.scene.patch_obstruction | self.scene.patch_hidden)

    @cached_property
    def row_sums(self) -> np.ndarray:
        """(n,) sum_j F_ij."""
        return np.asarray(self.F.sum(axis=1)).ravel()

    @cached_property
    def sky_factor(self) -> np.ndarray:
        """(n,) ``1 - sum_j F_ij`` of active patches (0 for inactive ones): the escape factor.

        Negative values are rows summing to more than 1: overlapping surfaces, or fill error.
        """
        return np.where(self.active, 1.0 - self.row_sums, 0.0)

    def grouped(self, by: str = "object") -> SurfaceFactors:
        """F summed back to the input surfaces: ``"object"`` or ``"face"``.

        For a View3D model, objects are its output surfaces (``cmb`` surfaces merged) and faces
        its ``S`` lines; for an OBJ, the ``o``/``g`` objects and the ``f`` faces.

        Examples
        --------
        >>> import numpy as np, radiosity
        >>> scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
        >>> vf = radiosity.compute_view_factors(scene, max_patch_size=0.5, cache=False)
        >>> vf.F.shape, vf.grouped("object").F.shape
        ((24, 24), (6, 6))
        >>> bool(np.allclose(vf.grouped("object").row_sums, 1.0, atol=1e-6))
        True
        """
        if by not in GROUPINGS:
            raise ValueError(f"by must be one of {GROUPINGS}, got {by!r}")
        scene = self.scene
        if by == "object":
            group, labels = scene.patch_object, list(scene.objects)
        else:
            group = scene.patch_face
            count = int(group.max()) + 1 if len(group) else 0
            owner = np.zeros(count, np.int64)
            owner[group] = scene.patch_object
            labels = [f"{scene.objects[owner[f]]}#{f + 1}" for f in range(count)]
        group = np.where(self.active, group, -1)
        F, area, kept = group_factors(self.F, scene.patch_area, group)
        renumber = np.full(len(labels), -1, np.int64)
        renumber[kept] = np.arange(len(kept))
        patch_group = np.where(group >= 0, renumber[np.maximum(group, 0)], -1)
        emissivity = 1.0 - scene.reflectance.mean(axis=1)
        weighted = np.bincount(np.maximum(patch_group, 0), weights=np.where(patch_group >= 0, emissivity * scene.patch_area, 0.0),
                               minlength=len(kept))
        return SurfaceFactors(F, area, [labels[k] for k in kept], weighted / area, patch_group, by)
