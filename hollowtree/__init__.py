"""hollowtree: labelled architectural parts (domes, minarets, arches, pillars, walls) from
terrestrial laser scans, out of core.

The Python API (docs/api.md)::

    import hollowtree
    report = hollowtree.run("workflow.yaml")            # or a Workflow, and client=Client(...)
    scan = hollowtree.open(report.store)                 # labels as arrays or a table
    scan.class_name[:5], scan.to_arrow()

Subpackages (each a folder at the top of the source tree): ``hollowtree.tiling`` (the class
vocabulary, readers, the run store, ingest), ``hollowtree.primitives`` (RANSAC, DBSCAN,
stitching), ``hollowtree.scenes`` (synthetic and procedural scans), ``hollowtree.hollownet``
(the voxel CNN), ``hollowtree.tree`` (the hierarchical tree) and ``hollowtree.pipeline``
(stages, workflows, the command line).
"""

from __future__ import annotations

from pathlib import Path as _Path

_source = _Path(__file__).resolve().parent.parent
if (_source / "pyproject.toml").is_file() and (_source / "pipeline" / "__init__.py").is_file():
    # A source checkout keeps the subpackages beside this folder, where the design card puts
    # them (pipeline/, tiling/, tree/, ...); a wheel installs them inside it.
    __path__.append(str(_source))

__version__ = "0.1.0"
__all__ = ["Workflow", "LabelledScan", "load_workflow", "open", "run", "__version__"]


def __getattr__(name: str):
    # Lazy: ``import hollowtree`` stays light (the command line imports it first).
    if name in ("run", "open", "LabelledScan"):
        from hollowtree import api

        return getattr(api, name)
    if name in ("Workflow", "load_workflow"):
        from hollowtree.pipeline import workflow

        return getattr(workflow, name)
    raise AttributeError(f"module 'hollowtree' has no attribute {name!r}")
