"""Doctests of the package modules, imported under their one name (``hollowtree.tiling.grid``).

pytest's own ``--doctest-modules`` would import ``tiling/grid.py`` as a top-level
``tiling.grid``: a second copy of every module, and numba caches (``__pycache__/*.nbi``)
written under names an installed or out-of-tree run cannot import.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest
from _pytest.doctest import DoctestModule

REPO = Path(__file__).resolve().parent
#: The folders that install as ``hollowtree.<folder>``.
PACKAGES = ("tiling", "primitives", "scenes", "hollownet", "tree", "pipeline")


def module_name(path: Path) -> str | None:
    """``tiling/grid.py`` -> ``hollowtree.tiling.grid``, ``hollowtree/errors.py`` ->
    ``hollowtree.errors``; None outside the package (and for ``__main__``)."""
    try:
        rel = path.resolve().relative_to(REPO).with_suffix("")
    except ValueError:
        return None
    if not rel.parts or rel.name == "__main__" or rel.parts[0] not in ("hollowtree", *PACKAGES):
        return None
    parts = rel.parts[1:] if rel.parts[0] == "hollowtree" else rel.parts  # hollowtree/errors.py
    parts = parts[:-1] if rel.name == "__init__" else parts
    return ".".join(("hollowtree", *parts))


class PackageDoctests(DoctestModule):
    def _getobj(self):
        return importlib.import_module(module_name(self.path))


def pytest_collect_file(file_path: Path, parent: pytest.Collector):
    if file_path.suffix == ".py" and module_name(file_path) is not None:
        return PackageDoctests.from_parent(parent, path=file_path)
    return None
