"""The house rules that a reviewer would otherwise check by hand."""

from __future__ import annotations

import ast
from pathlib import Path

import hollowtree.tree
from hollowtree.tiling import classes

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ["pipeline", "tiling", "tree", "hollownet", "primitives", "scenes"]
# Modules allowed to touch the outside world (files, CLI, cluster): the edges.
EDGE_MODULES = {"pipeline/cli.py", "pipeline/export.py", "pipeline/fuzz.py", "pipeline/graph.py",
                "pipeline/hollownet_cmd.py",
                "pipeline/workflow.py",
                "scenes/synth.py", "tiling/readers.py", "tiling/store.py"}
FORBIDDEN_IN_KERNELS = {"dask", "zarr", "laspy", "yaml"}


def _top(name: str) -> str:
    """The package an import names: ``hollowtree.tree.build`` -> ``tree``; ``numpy.linalg`` -> ``numpy``."""
    parts = name.split(".")
    return parts[1] if parts[0] == "hollowtree" and len(parts) > 1 else parts[0]


def _imports(path: Path) -> set[str]:
    mods: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            mods |= {_top(a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            mods.add(_top(node.module))
    return mods


def _modules():
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            yield path.relative_to(REPO).as_posix(), path


def test_top_level_layout():
    for name in ["pyproject.toml", "README.md", "hollowtree", "pipeline", "tiling", "tree", "hollownet",
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
    """Class names appear as a table only in tiling/classes.py."""
    names = {"ground", "wall", "roof", "arch", "dome", "minaret", "pillar", "other"}
    for rel, path in _modules():
        if rel == "tiling/classes.py":
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


def test_no_upward_imports():
    floor = {"tiling": 0, "primitives": 0, "scenes": 1, "hollownet": 1, "tree": 2, "pipeline": 3}
    for rel, path in _modules():
        own = floor[rel.split("/")[0]]
        for mod in _imports(path) & floor.keys():
            assert floor[mod] <= own, f"{rel} imports {mod}, a floor above it"
