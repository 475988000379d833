"""Collection rules for the whole repository (doctests in radiosity/, notebooks, tests/)."""

collect_ignore = ["radiosity/__main__.py", "bench", "build", "docs"]
