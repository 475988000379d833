"""The package layout reads as the pipeline: no import cycle, no import from a stage to a later one.

Every import of every module counts, including the ones inside functions (they hide cycles from
Python but not from a reader). ``STAGES`` is the pipeline in order (docs/layout.md draws it); a
module may import its own stage and earlier ones only.
"""

from __future__ import annotations

import ast
from fnmatch import fnmatch
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "radiosity"

# The pipeline, first stage first. Patterns match dotted module names (a package is its __init__).
STAGES: list[tuple[str, tuple[str, ...]]] = [
    ("foundation", ("radiosity._errors", "radiosity._tol", "radiosity._validate", "radiosity._startup",
                    "radiosity._memory", "radiosity.options")),
    ("geometry", ("radiosity.geometry", "radiosity.geometry.*", "radiosity._geometry_kernels")),
    ("reading", ("radiosity.io", "radiosity.io._text", "radiosity.io._files", "radiosity.io._obj_bulk",
                 "radiosity.io.obj")),
    ("scene", ("radiosity._ngon", "radiosity._patches_bulk", "radiosity.patches", "radiosity.imprint", "radiosity._checks",
               "radiosity._lightpaths_chunks", "radiosity._lightpaths", "radiosity.io.view3d", "radiosity.scene")),
    ("formfactors", ("radiosity.formfactors", "radiosity.formfactors.*")),
    ("visibility", ("radiosity.visibility", "radiosity.visibility.*")),
    ("methods", ("radiosity.methods", "radiosity.methods.*")),
    ("solution", ("radiosity.factors", "radiosity.enclosure", "radiosity.solution", "radiosity.solve",
                  "radiosity.exchange")),
    ("output", ("radiosity.viz", "radiosity.io._swap", "radiosity.io.export", "radiosity.io.html")),
    ("interface", ("radiosity", "radiosity.__main__", "radiosity._kernels", "radiosity.cli", "radiosity.cli.*")),
    # The measured alternatives stand apart: they may use the pipeline, nothing uses them.
    ("alternatives", ("radiosity.alternatives", "radiosity.alternatives.*")),
]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def all_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports_of(path: Path, modules: dict[str, Path]) -> set[str]:
    """Modules of the package that ``path`` imports, anywhere in its body."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "radiosity")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            elif node.module and node.module.split(".")[0] == "radiosity":
                target = node.module
            else:
                continue
            for alias in node.names:  # `from . import _tol` imports the module _tol
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in modules else target)
    return {m for m in found if m in modules and m != name}


def stage_of(module: str) -> int:
    for index, (_, patterns) in enumerate(STAGES):
        if any(fnmatch(module, p) for p in patterns):
            return index
    raise AssertionError(f"{module} has no stage: add it to STAGES in tests/test_layout.py and to docs/layout.md")


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    modules = all_modules()
    return {name: imports_of(path, modules) for name, path in modules.items()}


def test_every_module_has_a_stage(graph):
    for module in graph:
        stage_of(module)


def test_no_import_runs_to_a_later_stage(graph):
    backwards = [f"{a} ({STAGES[stage_of(a)][0]}) imports {b} ({STAGES[stage_of(b)][0]})"
                 for a, targets in graph.items() for b in sorted(targets) if stage_of(b) > stage_of(a)]
    assert not backwards, "\n".join(backwards)


def test_nothing_in_the_pipeline_uses_the_alternatives(graph):
    alternatives = [i for i, (stage, _) in enumerate(STAGES) if stage == "alternatives"][0]
    users = [a for a, targets in graph.items() for b in targets
             if stage_of(b) == alternatives and stage_of(a) != alternatives]
    assert not users


def test_the_numpy_references_serve_the_tests_only(graph):
    users = [a for a, targets in graph.items() for b in targets if b.endswith("._reference")]
    assert not users, users


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (a list of modules, first repeated last), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


def test_the_import_graph_has_no_cycle(graph):
    cycle = find_cycle(graph)
    assert cycle is None, " -> ".join(cycle)


def test_find_cycle_finds_a_hidden_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_function_level_imports_count(graph):
    # solution.py imports the visibility stage only inside Solution.irradiance
    assert "radiosity.visibility" in graph["radiosity.solution"]


def test_every_subpackage_ships():
    # pyproject lists the packages by hand (radiosity.meshes lives outside the tree), so a new
    # folder is missing from `pip install .` until it is added there: the hierarchical solver was.
    import tomllib

    pyproject = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())
    shipped = set(pyproject["tool"]["setuptools"]["packages"])
    found = {module_name(init) for init in PACKAGE.rglob("__init__.py")}
    assert found <= shipped, f"not in pyproject's packages: {sorted(found - shipped)}"
