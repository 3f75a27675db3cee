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

from hollowtree.exports import lazy_exports as _lazy_exports  # noqa: E402

__version__ = "0.1.0"
# Lazy: ``import hollowtree`` stays light (the command line imports it first).
_names, __getattr__ = _lazy_exports(__name__, {"api": "LabelledScan open run",
                                               "pipeline.workflow": "Workflow load_workflow"})
__all__ = [*_names, "__version__"]
