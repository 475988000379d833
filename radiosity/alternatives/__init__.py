"""Measured alternatives that no stage of the pipeline uses: kept to compare against.

- ``_stark``: Stark's closed forms for polygon-to-polygon factors (``docs/stark.md``).
- ``hemicube``: the hemicube approximation of form factors (``tests/test_hemicube.py``).
"""
