"""The house rules that a reviewer would otherwise check by hand."""

from __future__ import annotations

import ast
from pathlib import Path

import hollowtree.tree
from hollowtree import classes

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ["pipeline", "tiling", "tree", "hollownet", "primitives", "scenes"]
#: The ground floor: ``hollowtree/`` modules that every package may import (``params``: the
#: stages' parameter declarations and their one validator; ``exports``: a package's lazy names).
GROUND = {"arrays", "classes", "errors", "columns", "params", "exports"}
#: Floors, lowest first: a module imports only from its own floor and those below.
FLOOR = {"ground": 0, "tiling": 1, "primitives": 1, "scenes": 2, "hollownet": 2, "tree": 3, "pipeline": 4,
         "api": 5}
# Modules allowed to touch the outside world (files, CLI, cluster): the edges.
EDGE_MODULES = {"pipeline/cli.py", "pipeline/cli_args.py", "pipeline/export.py", "pipeline/fuzz.py", "pipeline/graph.py",
                "pipeline/hollownet_cmd.py", "pipeline/view.py",
                "pipeline/workflow.py",
                "scenes/synth.py", "tiling/readers.py", "tiling/_points.py", "tiling/read_las.py",
                "tiling/read_ply.py", "tiling/read_e57.py", "tiling/read_pdal.py", "tiling/store.py"}
FORBIDDEN_IN_KERNELS = {"dask", "zarr", "laspy", "yaml"}


def _top(name: str) -> str:
    """The floor or package an import names: ``hollowtree.tree.build`` -> ``tree``,
    ``hollowtree.errors`` -> ``ground``, ``hollowtree`` -> ``api``; ``numpy.linalg`` -> ``numpy``."""
    parts = name.split(".")
    if parts[0] != "hollowtree":
        return parts[0]
    if len(parts) == 1:
        return "api"
    return "ground" if parts[1] in GROUND else "api" if parts[1] == "api" else parts[1]


def _imports(path: Path) -> set[str]:
    mods: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            mods |= {_top(a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            mods.add(_top(node.module))
    return mods


def _modules():
    for path in sorted((REPO / "hollowtree").glob("*.py")):
        yield path.relative_to(REPO).as_posix(), path
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            yield path.relative_to(REPO).as_posix(), path


def test_top_level_layout():
    for name in ["pyproject.toml", "README.md", "LICENSE", "CITATION.cff", "CHANGELOG.md", "hollowtree", "pipeline", "tiling", "tree", "hollownet",
                 "tests", "workflows", "docs", "benchmarks", ".ci/run"]:
        assert (REPO / name).exists(), name


def test_tree_is_ours_not_dm_tree():
    assert Path(hollowtree.tree.__file__).resolve().is_relative_to(REPO)


def test_one_import_name():
    """Every module imports its siblings through ``hollowtree``, never as a top-level
    package (an installed wheel has no top-level ``tree``, ``pipeline``, ...)."""
    for rel, path in [*_modules(), *((p.relative_to(REPO).as_posix(), p) for p in
                                     sorted((REPO / "tests").glob("*.py")))]:
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and node.module and node.level == 0
                     else [])
            for name in names:
                assert name.split(".")[0] not in PACKAGES, f"{rel}:{node.lineno} imports {name}"


def test_kernels_stay_pure():
    for rel, path in _modules():
        if rel in EDGE_MODULES:
            continue
        bad = _imports(path) & FORBIDDEN_IN_KERNELS
        assert not bad, f"{rel} imports {bad}; only edge modules may"


def test_class_vocabulary_is_defined_once():
    """Class names appear as a table only in hollowtree/classes.py."""
    names = {"ground", "wall", "roof", "arch", "dome", "minaret", "pillar", "other"}
    for rel, path in _modules():
        if rel == "hollowtree/classes.py":
            continue
        tree_ = ast.parse(path.read_text())
        exported = {
            id(n.value)
            for n in ast.walk(tree_)
            if isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in n.targets)
        }
        for node in ast.walk(tree_):
            if id(node) in exported:  # __all__ may export builders called dome, arch, ...
                continue
            if isinstance(node, (ast.List, ast.Tuple, ast.Set, ast.Dict)):
                elts = node.keys if isinstance(node, ast.Dict) else node.elts
                strs = {e.value for e in elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
                assert len(strs & names) < 4, f"{rel}:{node.lineno} redefines class names"
    assert classes.CLASS_NAMES[5] == "dome"
    assert classes.NUM_CLASSES == 9


def _floor(rel: str) -> str:
    top, name = rel.split("/")[0], Path(rel).stem
    if top == "hollowtree":
        return "ground" if name in GROUND else "api"
    return top


def test_no_upward_imports():
    seen = set()
    for rel, path in _modules():
        own = FLOOR[_floor(rel)]
        seen.add(_floor(rel))
        for mod in _imports(path) & FLOOR.keys():
            assert FLOOR[mod] <= own, f"{rel} imports {mod}, a floor above it"
    assert seen == set(FLOOR)


def test_the_ground_floor_imports_only_itself():
    for name in sorted(GROUND):
        path = REPO / "hollowtree" / f"{name}.py"
        assert not (_imports(path) - {"ground", "__future__", "typing", "enum", "numpy", "dataclasses", "collections",
                                      "functools", "math", "numbers", "types", "importlib"}), name
