"""Solution methods: how the radiosity system is built and solved.

- ``uniform``: the uniform matrix method: every patch pair's form factor in one sparse matrix
  (filled in this process, on a Dask cluster, or out of core into shards), then a sparse solve.
- ``hierarchical``: element quadtrees per patch and links at the coarsest level an error bound
  allows (Hanrahan, Salzman & Aupperle 1991), gathered and pushed-pulled on the leaves.
"""
