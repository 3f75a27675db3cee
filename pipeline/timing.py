"""Where a run's time went, from its completion records, and what more workers would give.

Every unit record holds ``wall_s``, ``cpu_s``, ``worker`` and ``finished``
(:meth:`tiling.store.RunStore.record`); every stage in the store's ``stages`` attribute
holds ``wall_s`` and ``driver_s`` (the seconds outside its task waves, in the driver
alone; :func:`pipeline.graph.timed_stage`). A stage runs its units in **waves**: the
tasks of one wave run in parallel and the next wave starts when the last of them ends.
:func:`predict_seconds` list-schedules each wave's recorded units (longest first) on
``workers`` workers and adds the stages' driver seconds: the makespan the recorded units
allow, before contention for memory bandwidth and disk, which a machine with more
cores adds.

Pure Python on plain dicts: ``hollowtree status`` and ``benchmarks/bench_scale.py`` read
the records and call these.
"""

from __future__ import annotations

import heapq
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["UNIT_BALANCE", "WAVES", "Wave", "balance", "lpt_makespan", "predict_seconds", "unit_points", "waves"]

#: The most points a stage's unit should hold, as a multiple of the median unit of its
#: wave (issue 44): the coarse stage's blocks and the tree's batches are sized for it.
UNIT_BALANCE = 3.0

#: ``(stage, wave, record stage)`` in the order a run makes them. A dense tile's ingest
#: parts run beside the whole tiles, its copy units after them. The coarse stage's
#: ``coarse`` records are two waves: a tile segmented whole (``n_blocks`` 1) runs beside
#: the blocks of the big tiles, a big tile's join after them.
WAVES = (
    ("ingest", "map", "ingest.map"),
    ("ingest", "tiles", "ingest"),
    ("ingest", "tiles", "ingest.parts"),
    ("ingest", "copies", "ingest.copies"),
    ("coarse", "plan", "coarse.plan"),
    ("coarse", "tiles", "coarse.blocks"),
    ("coarse", "tiles", "coarse"),
    ("coarse", "joins", "coarse"),
    ("coarse", "pairs", "coarse.pairs"),
    ("coarse", "parts", "coarse.csr_parts"),
    ("coarse", "csr", "coarse.csr"),
    ("tree", "batches", "tree"),
    ("tree", "spread", "tree.spread"),
    ("labels", "tiles", "labels_tiles"),
    ("labels", "ranges", "labels"),
)


@dataclass(frozen=True)
class Wave:
    """The recorded units of one wave: their wall seconds, CPU seconds and points."""

    stage: str
    name: str
    wall: tuple[float, ...]
    cpu: tuple[float, ...]
    points: tuple[int, ...]
    workers: int


def unit_points(info: Mapping[str, Any]) -> int:
    """The points a unit record says it handled (0 where it does not say).

    >>> unit_points({"n_points": 5}), unit_points({"tiles": {"0": 2, "3": 4}}), unit_points({})
    (5, 6, 0)
    """
    for key in ("n_points", "n_own", "n_labelled"):
        if key in info:
            return int(info[key])
    if isinstance(info.get("tiles"), Mapping):
        return int(sum(info["tiles"].values()))
    return 0


def waves(records: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> list[Wave]:
    """The waves of a store's records (``record stage -> unit -> info``), in run order;
    units without timing (records of an older store) are left out, empty waves too.

    >>> r = {"tree": {"0": {"wall_s": 2.0, "cpu_s": 1.9, "n_points": 10, "worker": "a"},
    ...               "1": {"wall_s": 1.0, "cpu_s": 1.0, "n_points": 5, "worker": "b"}}}
    >>> [(w.stage, w.name, w.wall, w.points, w.workers) for w in waves(r)]
    [('tree', 'batches', (2.0, 1.0), (10, 5), 2)]
    """
    out: list[Wave] = []
    merged: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for stage, name, rec_stage in WAVES:
        units = [info for info in records.get(rec_stage, {}).values() if "wall_s" in info]
        if rec_stage == "coarse":
            joined = name == "joins"
            units = [u for u in units if (int(u.get("n_blocks", 1)) > 1) == joined]
        merged.setdefault((stage, name), []).extend(units)
    for (stage, name), units in merged.items():
        if units:
            out.append(Wave(stage, name, tuple(float(u["wall_s"]) for u in units),
                            tuple(float(u.get("cpu_s", 0.0)) for u in units),
                            tuple(unit_points(u) for u in units), len({u.get("worker") for u in units})))
    return out


def balance(points: Sequence[int]) -> float | None:
    """The largest of a wave's unit sizes over their median; units of no points (an empty
    tile's, which do no work) are left out; None when none is left.

    >>> balance([10, 20, 30, 90]), balance([0, 0, 5, 5]), balance([0])
    (3.6, 1.0, None)
    """
    pts = sorted(p for p in points if p > 0)
    if not pts:
        return None
    n = len(pts)
    med = pts[n // 2] if n % 2 else (pts[n // 2 - 1] + pts[n // 2]) / 2
    return pts[-1] / med if med else None


def lpt_makespan(durations: Sequence[float], workers: int) -> float:
    """Makespan of ``durations`` list-scheduled longest first on ``workers`` workers.

    >>> lpt_makespan([3, 3, 2, 2, 2], 2), lpt_makespan([5, 1], 8), lpt_makespan([], 4)
    (7.0, 5.0, 0.0)
    """
    if workers < 1:
        raise ValueError(f"workers must be at least 1; got {workers}")
    ends = [0.0] * min(workers, max(len(durations), 1))
    for d in sorted(durations, reverse=True):
        heapq.heapreplace(ends, ends[0] + float(d))
    return max(ends)


def predict_seconds(wave_list: Sequence[Wave], driver_s: Mapping[str, float], workers: int, *,
                    repeat: float = 1.0) -> float:
    """Predicted seconds of the recorded stages on ``workers`` workers: every wave's
    makespan plus the driver's seconds of every stage.

    ``repeat`` projects a scan ``repeat`` times larger cut into units of the same sizes:
    every wave holds its units ``repeat`` times (rounded to whole units, cycling through
    them) and the driver's seconds grow ``repeat`` times (its work is linear in the
    points: stitching, tables).

    >>> w = [Wave("tree", "batches", (2.0, 2.0, 2.0, 2.0), (1, 1, 1, 1), (0, 0, 0, 0), 2)]
    >>> predict_seconds(w, {"tree": 0.5}, 2), predict_seconds(w, {"tree": 0.5}, 4)
    (4.5, 2.5)
    >>> predict_seconds(w, {"tree": 0.5}, 4, repeat=2.0)
    5.0
    """
    if repeat <= 0:
        raise ValueError(f"repeat must be positive; got {repeat}")
    total = repeat * sum(driver_s.values())
    for w in wave_list:
        n = max(1, round(len(w.wall) * repeat))
        total += lpt_makespan([w.wall[i % len(w.wall)] for i in range(n)], workers)
    return total
