"""Solution methods: ``hierarchical`` (element quadtrees and links); the uniform fill lives in ``radiosity.solve``."""
