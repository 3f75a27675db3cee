"""Where a run's time went, from its completion records, and what more workers would give.

Every unit record holds ``wall_s``, ``cpu_s``, ``worker`` and ``finished``
(:meth:`tiling.store.RunStore.record`); every stage in the store's ``stages`` attribute
holds ``wall_s`` and ``driver_s`` (the seconds outside its task waves, in the driver
alone; :func:`pipeline.graph.timed_stage`). A stage runs its units in **waves**. Most
waves are barriers: the next wave starts when the last unit of the one before ends. A
**pipelined** wave (``PIPELINED``) is not: each of its units waits only for the units of
the same tile in the wave it follows (the coarse stage's block tasks wait for their
tile's plan, a tile's join for its blocks), so those waves run as one graph.
:func:`predict_seconds` list-schedules the recorded units on ``workers`` workers, a
barrier wave longest first, a pipelined chain by :func:`unit_priority` as the stage
submits them, and adds the stages' driver seconds: the makespan the recorded units
allow, before contention for memory bandwidth and disk, which a machine with more
cores adds.

Pure Python on plain dicts: ``hollowtree status`` and ``benchmarks/bench_scale.py`` read
the records and call these; the coarse stage takes its task priorities from here.
"""

from __future__ import annotations

import heapq
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["PIPELINED", "UNIT_BALANCE", "WAVES", "Wave", "balance", "dag_makespan", "lpt_makespan", "predict_seconds",
           "unit_points", "unit_priority", "waves"]

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
    ("coarse", "spacing", "coarse.spacing"),
    ("coarse", "plan", "coarse.plan"),
    ("coarse", "normals", "coarse.normals"),
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

#: ``(stage, wave) -> the waves it may follow`` (the first of them a run recorded), unit
#: by unit: each unit of the wave starts once the units of the same tile (the record's
#: unit name up to its first ``.``) in the wave it follows have ended, not once that whole
#: wave has. The coarse stage submits them so (:func:`pipeline.coarse.run_coarse`): a big
#: tile's normals as soon as its plan ends, its blocks as soon as its normals do (or its
#: plan, without normals tasks), its join as soon as its blocks do; a tile segmented whole
#: waits for its normals or for nothing.
PIPELINED = {("coarse", "normals"): (("coarse", "plan"),),
             ("coarse", "tiles"): (("coarse", "normals"), ("coarse", "plan")),
             ("coarse", "joins"): (("coarse", "tiles"),)}

#: Waves whose units go before any other unit that is ready at the same time: a plan
#: unlocks its tile's normals and blocks, normals their tile's units, the longest of the
#: stage; a join ends its tile and frees its blocks' inputs.
FIRST = frozenset({("coarse", "plan"), ("coarse", "normals"), ("coarse", "joins")})


def unit_priority(stage: str, wave: str, points: int) -> int:
    """The scheduling priority of a unit of a pipelined chain (higher runs first): the
    units of a ``FIRST`` wave, then the others by ``points``, the points of the unit's
    tile in its wave (the largest first: the longest-first rule of a barrier wave, by
    tile). A block of a cut tile goes by its whole tile's points, not its own: the tile
    ends (its join) only when its last block does, so its blocks go together and before
    smaller whole tiles (on 16 workers the coarse chain of the 100 M-point benchmark
    predicts 41.4 s by the blocks' own points, 37.2 s by their tile's). The coarse
    stage gives its Dask tasks these priorities; :func:`predict_seconds` schedules the
    recorded units by them.

    >>> unit_priority("coarse", "plan", 0) > unit_priority("coarse", "tiles", 2_000_000) > unit_priority(
    ...     "coarse", "tiles", 5)
    True
    """
    return (1 << 50) + int(points) if (stage, wave) in FIRST else int(points)


@dataclass(frozen=True)
class Wave:
    """The recorded units of one wave: their wall seconds, CPU seconds, points, the
    number of workers that ran them, and each unit's tile (the record's unit name up to
    its first ``.``; what a ``PIPELINED`` wave's units wait for)."""

    stage: str
    name: str
    wall: tuple[float, ...]
    cpu: tuple[float, ...]
    points: tuple[int, ...]
    workers: int
    tiles: tuple[str, ...] = ()


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
    merged: dict[tuple[str, str], list[tuple[str, Mapping[str, Any]]]] = {}
    for stage, name, rec_stage in WAVES:
        units = [(unit, info) for unit, info in records.get(rec_stage, {}).items() if "wall_s" in info]
        if rec_stage == "coarse":
            joined = name == "joins"
            units = [(k, u) for k, u in units if (int(u.get("n_blocks", 1)) > 1) == joined]
        merged.setdefault((stage, name), []).extend(units)
    for (stage, name), units in merged.items():
        if units:
            out.append(Wave(stage, name, tuple(float(u["wall_s"]) for _, u in units),
                            tuple(float(u.get("cpu_s", 0.0)) for _, u in units),
                            tuple(unit_points(u) for _, u in units), len({u.get("worker") for _, u in units}),
                            tuple(str(k).split(".", 1)[0] for k, _ in units)))
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


def dag_makespan(durations: Sequence[float], after: Sequence[Sequence[int]], priority: Sequence[int],
                 workers: int) -> float:
    """Makespan of units with dependencies list-scheduled on ``workers`` workers: unit
    ``i`` (``durations[i]`` seconds) is ready once every unit in ``after[i]`` has ended;
    a free worker takes the ready unit of the highest ``priority`` (ties: the longer,
    then the first). Without dependencies and with priorities by duration it is
    :func:`lpt_makespan`.

    >>> dag_makespan([1, 4, 1], [[], [0], [1]], [9, 0, 9], 2)  # a chain: 1 + 4 + 1
    6.0
    >>> dag_makespan([1, 4, 4, 3], [[], [0], [], []], [9, 4, 4, 3], 2)  # 0 first, then 1 and 2 side by side
    7.0
    """
    if workers < 1:
        raise ValueError(f"workers must be at least 1; got {workers}")
    n = len(durations)
    waiting = [len(a) for a in after]
    children: list[list[int]] = [[] for _ in range(n)]
    for i, a in enumerate(after):
        for j in a:
            children[j].append(i)
    ready = [(-priority[i], -float(durations[i]), i) for i in range(n) if not waiting[i]]
    heapq.heapify(ready)
    running: list[tuple[float, int]] = []
    now, free = 0.0, workers
    while ready or running:
        while free and ready:
            _, _, i = heapq.heappop(ready)
            heapq.heappush(running, (now + float(durations[i]), i))
            free -= 1
        now, i = heapq.heappop(running)
        free += 1
        for c in children[i]:
            waiting[c] -= 1
            if not waiting[c]:
                heapq.heappush(ready, (-priority[c], -float(durations[c]), c))
    return now


def _chain_makespan(chain: Sequence[Wave], workers: int, repeat: float) -> float:
    """Makespan of a chain of pipelined waves (a wave, then those ``PIPELINED`` after it):
    each unit waits for the units of its tile in the wave before it. With ``repeat``,
    the chain's tiles are repeated (rounded to whole tiles, cycling), each copy with its
    own units."""
    tiles = sorted({t for w in chain for t in w.tiles})
    n = max(1, round(len(tiles) * repeat))
    durations: list[float] = []
    after: list[list[int]] = []
    priority: list[int] = []
    for copy in range(n):
        tile = tiles[copy % len(tiles)]
        before: list[int] = []
        for w in chain:
            mine = [i for i, t in enumerate(w.tiles) if t == tile]
            tile_points = sum(w.points[i] for i in mine)  # a cut tile's blocks: the tile's points
            now = []
            for i in mine:
                now.append(len(durations))
                durations.append(w.wall[i])
                after.append(list(before))
                priority.append(unit_priority(w.stage, w.name, tile_points))
            before = now or before
    return dag_makespan(durations, after, priority, workers)


def predict_seconds(wave_list: Sequence[Wave], driver_s: Mapping[str, float], workers: int, *,
                    repeat: float = 1.0) -> float:
    """Predicted seconds of the recorded stages on ``workers`` workers: every barrier
    wave's makespan, every chain of ``PIPELINED`` waves' makespan as one graph, plus the
    driver's seconds of every stage.

    ``repeat`` projects a scan ``repeat`` times larger cut into units of the same sizes:
    every wave holds its units ``repeat`` times (rounded to whole units, cycling through
    them; a pipelined chain its tiles) and the driver's seconds grow ``repeat`` times (its
    work is linear in the points: stitching, tables).

    >>> w = [Wave("tree", "batches", (2.0, 2.0, 2.0, 2.0), (1, 1, 1, 1), (0, 0, 0, 0), 2)]
    >>> predict_seconds(w, {"tree": 0.5}, 2), predict_seconds(w, {"tree": 0.5}, 4)
    (4.5, 2.5)
    >>> predict_seconds(w, {"tree": 0.5}, 4, repeat=2.0)
    5.0

    A big tile's plan (1 s), its two blocks (4 s each) and join (1 s) beside a whole
    tile of 6 s: on 2 workers the whole tile runs while the plan and the blocks do.

    >>> c = [Wave("coarse", "plan", (1.0,), (1.0,), (0,), 1, ("0",)),
    ...      Wave("coarse", "tiles", (4.0, 4.0, 6.0), (4.0, 4.0, 6.0), (5, 5, 9), 1, ("0", "0", "1")),
    ...      Wave("coarse", "joins", (1.0,), (1.0,), (10,), 1, ("0",))]
    >>> predict_seconds(c, {}, 2), predict_seconds(c, {}, 1)
    (10.0, 16.0)
    """
    if repeat <= 0:
        raise ValueError(f"repeat must be positive; got {repeat}")
    total = repeat * sum(driver_s.values())
    chains: list[list[Wave]] = []
    for w in wave_list:
        follows = PIPELINED.get((w.stage, w.name), ())
        if chains and (chains[-1][-1].stage, chains[-1][-1].name) in follows and w.tiles:
            chains[-1].append(w)
        else:
            chains.append([w])
    for chain in chains:
        if len(chain) > 1:
            total += _chain_makespan(chain, workers, repeat)
        else:
            w = chain[0]
            n = max(1, round(len(w.wall) * repeat))
            total += lpt_makespan([w.wall[i % len(w.wall)] for i in range(n)], workers)
    return total
