"""The uniform matrix method: fill the patch-to-patch view-factor matrix, then solve (I - rho F) B = E.

- ``assembly``: the fill (form factors times visibility, block by block) and its settings.
- ``cache``: form factors stored on disk for the same geometry and accuracy settings.
- ``cluster``: the same fill on a Dask cluster.
- ``shards``: the matrix written out of core, block by block, and read back lazily.
- ``system``: the sparse linear solvers and the energy balance.
"""
