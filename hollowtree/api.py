"""The Python API: run a workflow, open a labelled store.

``hollowtree.run`` is ``hollowtree run`` for a notebook (an existing ``distributed.Client``
is used as it is and left open); ``hollowtree.open`` reads a finished store's labels as
NumPy arrays in the input's point order, or as an Arrow table / pandas DataFrame.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hollowtree.classes import CLASS_NAMES
from hollowtree.errors import PipelineError
from hollowtree.pipeline.workflow import Workflow, load_workflow

__all__ = ["LabelledScan", "open", "run"]

#: The per-point label arrays of a store (``labels/<name>``, docs/store.md), in input order.
LABELS = ("class", "instance", "segment", "score", "primitive")


def run(workflow: str | Path | Workflow, client: Any = None, *, overrides: Sequence[str] = (),
        progress: bool = False) -> LabelledScan:
    """Run every stage of a workflow (resuming what its store already holds) and open the result.

    Parameters
    ----------
    workflow
        A workflow file (YAML) or a :class:`~hollowtree.pipeline.workflow.Workflow`.
    client
        An existing ``distributed.Client`` to run the tasks on (a notebook's, a dask-jobqueue
        or dask-kubernetes cluster's); it stays open. ``None``: the workflow's ``cluster:``.
    overrides
        ``key=value`` settings, as ``hollowtree run --set`` takes them (files only).
    progress
        Progress bars (on a terminal) and a line per stage.

    Raises
    ------
    hollowtree.errors.PipelineError
        One line naming the file or key and what is wrong (``WorkflowError``, ``ConfigError``, ...).
    """
    from hollowtree.pipeline.run import run_workflow

    if isinstance(workflow, Workflow):
        if overrides:
            raise TypeError("overrides apply to a workflow file; change the Workflow's fields instead")
        wf = workflow
    else:
        wf = load_workflow(workflow, list(overrides))
    run_workflow(wf, progress=progress, say=print if progress else (lambda line: None), client=client)
    return open(wf.store)


def open(store: str | Path) -> LabelledScan:  # noqa: A001  (hollowtree.open, as the issue names it)
    """Open the labels of a finished run store (a path or an fsspec URL), read only.

    Raises
    ------
    hollowtree.errors.PipelineError
        The store does not exist, is not a hollowtree store, or has no complete labels.
    """
    from hollowtree.pipeline.labels import require_labels
    from hollowtree.tiling.store import RunStore

    rs = RunStore.open(store)
    require_labels(rs)
    return LabelledScan(rs)


def _label_array(name: str, doc: str) -> Any:
    """A read-only property: the store's ``labels/<name>`` array, read on first use."""

    def get(self: LabelledScan) -> np.ndarray:
        return self._label(name)

    return property(get, doc=doc)


class LabelledScan:
    """A finished run store's labels, read on first use.

    The label arrays (:attr:`class_id`, :attr:`instance`, :attr:`segment`, :attr:`score`,
    :attr:`primitive`) hold one entry per input point, in the input's order (file 0's
    points first): the order of the exported LAS.
    """

    def __init__(self, store: Any) -> None:
        self._store = store
        self._cache: dict[str, np.ndarray] = {}

    def __repr__(self) -> str:
        return f"LabelledScan({self.url!r}, {len(self):,} points)"

    def __len__(self) -> int:
        return self._store.array_length("labels/class")

    @property
    def url(self) -> str:
        """The store's location."""
        return str(self._store.url)

    def _label(self, name: str) -> np.ndarray:
        if name not in self._cache:
            self._cache[name] = self._store.read_slice(f"labels/{name}")
        return self._cache[name]

    class_id = _label_array("class", "uint8 class per point (:data:`CLASS_NAMES` indexes it); 0 = not labelled.")
    instance = _label_array("instance", "uint32 element instance per point, unique in the store; 0 = none.")
    segment = _label_array("segment", "uint64 tree leaf per point (coarse segment << 20 | leaf node id); 0 = none.")
    score = _label_array("score", "float32 classifier score of each point's class.")
    primitive = _label_array("primitive",
                             "uint8 coarse primitive per point (plane, cylinder, sphere, cone, torus); 0 = none.")

    @property
    def class_name(self) -> np.ndarray:
        """The class name of each point (ground, wall, roof, arch, dome, minaret, pillar, ...)."""
        return np.asarray(CLASS_NAMES, dtype=object)[self.class_id]

    def counts(self) -> dict[str, int]:
        """Points per class name, for the classes that occur."""
        n = np.bincount(self.class_id, minlength=len(CLASS_NAMES))
        return {CLASS_NAMES[c]: int(n[c]) for c in np.flatnonzero(n)}

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """``(index, xyz)`` of the points the store holds: input positions (sorted) and world
        coordinates (float64, metres). Every input point, unless the ingest thinned the scan
        with ``voxel`` (then only the kept points)."""
        st = self._store
        attrs = st.attrs
        scale, offset = np.asarray(attrs["coords"]["scale"]), np.asarray(attrs["coords"]["offset"])
        idx, xyz = [], []
        for t in attrs["ingest"]["tiles"]:
            d = st.read_unit(f"tiles/{int(t)}", ["xyz", "index", "core"])
            idx.append(d["index"][d["core"]])
            xyz.append(d["xyz"][d["core"]] * scale + offset)
        if not idx:
            return np.zeros(0, np.uint64), np.zeros((0, 3))
        index, world = np.concatenate(idx), np.concatenate(xyz)
        order = np.argsort(index, kind="stable")
        return index[order], world[order]

    def to_arrow(self, *, xyz: bool = True) -> Any:
        """A ``pyarrow.Table``: ``index`` (and ``x, y, z`` with ``xyz``), ``class``,
        ``class_name`` (dictionary-encoded), ``instance``, ``segment``, ``score``,
        ``primitive``; one row per point the store holds (see :meth:`points`)."""
        import pyarrow as pa

        if xyz:
            index, world = self.points()
        else:
            index, world = np.arange(len(self), dtype=np.uint64), None
        cols: dict[str, Any] = {"index": index}
        if world is not None:
            cols.update(x=world[:, 0], y=world[:, 1], z=world[:, 2])
        cls = self.class_id[index]
        cols["class"] = cls
        cols["class_name"] = pa.DictionaryArray.from_arrays(
            pa.array(cls.astype(np.int32)), pa.array(list(CLASS_NAMES)))
        for name in LABELS[1:]:
            cols[name] = self._label(name)[index]
        return pa.table(cols)

    def to_pandas(self, *, xyz: bool = True) -> Any:
        """:meth:`to_arrow` as a pandas DataFrame (needs pandas, which hollowtree does not
        install)."""
        try:
            import pandas  # noqa: F401
        except ImportError:
            raise PipelineError("to_pandas needs pandas (pip install pandas); to_arrow() needs nothing more") from None
        return self.to_arrow(xyz=xyz).to_pandas()

    def segments(self) -> Any:
        """The coarse stage's segment table (``coarse/segments.parquet``) as a pyarrow Table."""
        return self._parquet("coarse/segments.parquet")

    def nodes(self) -> Any:
        """The hierarchical tree's node table (``tree/nodes.parquet``) as a pyarrow Table."""
        return self._parquet("tree/nodes.parquet")

    def _parquet(self, rel: str) -> Any:
        import fsspec
        import pyarrow.parquet as pq

        fs, root = fsspec.core.url_to_fs(self.url)
        path = f"{root.rstrip('/')}/{rel}"
        if not fs.exists(path):
            raise PipelineError(f"store {self.url} has no {rel}")
        with fs.open(path, "rb") as f:
            return pq.read_table(f)
