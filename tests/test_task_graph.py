"""``pipeline.graph.run_graph``: tasks that make tasks as they end (the coarse stage's plans,
blocks and joins), on every runner; and ``pipeline.timing``'s prediction of such a graph."""

from __future__ import annotations

import threading
import time

import pytest

from hollowtree.pipeline.graph import Task, run_graph, task_runner
from hollowtree.pipeline.timing import Wave, dag_makespan, lpt_makespan, predict_seconds


def _double(x: int) -> int:
    return 2 * x


def _graph(log: list):
    """A plan per tile (returns its block count), then its blocks, then its join."""
    left: dict[int, int] = {}

    def then(tag, result):
        log.append((tag, result))
        kind, tile = tag[0], tag[1]
        if kind == "plan":
            left[tile] = result // 2
            return [Task(_double, (b,), 10, ("block", tile, b), "blocks") for b in range(left[tile])]
        if kind == "block":
            left[tile] -= 1
            if not left[tile]:
                return [Task(_double, (tile,), 100, ("join", tile), "joins")]
        return []

    first = [Task(_double, (n,), 100, ("plan", n), "plans") for n in (1, 2, 3)]
    first.append(Task(_double, (7,), 5, ("whole", 7), "whole"))
    return first, then


def _check(log: list) -> None:
    tags = [tag for tag, _ in log]
    assert len(tags) == 4 + (1 + 2 + 3) + 3, tags
    for tile in (1, 2, 3):
        blocks = [i for i, t in enumerate(tags) if t[:2] == ("block", tile)]
        assert len(blocks) == tile
        assert tags.index(("plan", tile)) < min(blocks)
        assert max(blocks) < tags.index(("join", tile))
    assert dict(log)[("block", 3, 2)] == 4
    assert dict(log)[("join", 2)] == 4


def test_sync_runner_runs_the_graph_as_it_grows_highest_priority_first():
    log: list = []
    first, then = _graph(log)
    with task_runner("sync", progress=False) as run:
        run_graph(run, first, then, "graph")
        assert run.task_seconds() > 0
    _check(log)
    tags = [tag for tag, _ in log]
    assert [t[0] for t in tags[:3]] == ["plan"] * 3  # priority 100 before the others
    assert tags[-1] == ("whole", 7)  # priority 5: after every block and join


def test_a_plain_runner_runs_the_graph_wave_by_wave():
    log: list = []
    waves: list[tuple[str, int]] = []

    def plain(fn, args_list, desc):
        waves.append((desc, len(args_list)))
        return [fn(*a) for a in args_list]

    first, then = _graph(log)
    run_graph(plain, first, then, "graph")
    _check(log)
    assert waves[:2] == [("plans", 3), ("whole", 1)]
    assert waves[2] == ("blocks", 6)


_STARTED: dict[str, float] = {}
_LOCK = threading.Lock()


def _job(name: str, seconds: float) -> str:
    """A task of the thread workers below: notes when it starts (they share this module)."""
    with _LOCK:
        _STARTED[name] = time.perf_counter()
    time.sleep(seconds)
    return name


def test_a_local_cluster_runs_the_graph_beside_the_other_tasks():
    """Thread workers: a tile's blocks start while the long task of another tile still runs."""
    _STARTED.clear()
    started, job = _STARTED, _job

    def then(tag, result):
        return [Task(job, (f"block{b}", 0.05), 1, ("block", b)) for b in range(3)] if tag == "plan" else []

    first = [Task(job, ("long", 1.5), 1, "long"), Task(job, ("plan", 0.05), 100, "plan")]
    with task_runner(None, workers=2, processes=False, progress=False) as run:
        assert not run.serial  # tasks side by side: the coarse stage splits its normals
        run_graph(run, first, then, "graph")
    assert set(started) == {"long", "plan", "block0", "block1", "block2"}
    assert max(started[f"block{b}"] for b in range(3)) < started["long"] + 1.0  # not after the long task


def test_a_failing_task_raises_its_own_error_on_every_runner():
    def then(tag, result):
        return [Task(int, ("not a number",), 0, "bad")] if tag == "ok" else []

    for scheduler in ("sync", None):
        with task_runner(scheduler, workers=1, processes=False, progress=False) as run, \
                pytest.raises(ValueError, match="invalid literal"):
            run_graph(run, [Task(_double, (1,), 0, "ok")], then, "graph")


def test_the_prediction_schedules_a_pipelined_chain_as_one_graph():
    """Two big tiles (plan 1 s, blocks, join 1 s) and whole tiles on 4 workers: the blocks
    of the first planned tile start while the other plan and the whole tiles run."""
    plan = Wave("coarse", "plan", (1.0, 1.0), (1.0, 1.0), (0, 0), 1, ("0", "1"))
    tiles = Wave("coarse", "tiles", (3.0, 3.0, 3.0, 3.0, 2.0, 2.0), (0,) * 6,
                 (30, 30, 30, 30, 20, 20), 1, ("0", "0", "1", "1", "2", "3"))
    joins = Wave("coarse", "joins", (1.0, 1.0), (1.0, 1.0), (60, 60), 1, ("0", "1"))
    barrier = sum(lpt_makespan(w.wall, 4) for w in (plan, tiles, joins))
    chained = predict_seconds([plan, tiles, joins], {}, 4)
    assert barrier == 1.0 + 5.0 + 1.0
    # plans 0-1 and whole tiles 0-2; tile 0's blocks 1-4, tile 1's 2-5; joins 4-5 and 5-6
    assert chained == 6.0
    assert predict_seconds([plan, tiles, joins], {}, 1) == sum(plan.wall + tiles.wall + joins.wall)
    # the chain repeated: twice the tiles, each copy with its own units
    assert predict_seconds([plan, tiles, joins], {}, 1, repeat=2.0) == 2 * sum(plan.wall + tiles.wall + joins.wall)
    # waves that are not pipelined keep their barrier
    other = Wave("tree", "batches", (2.0, 2.0), (2.0, 2.0), (1, 1), 1, ("0", "1"))
    assert predict_seconds([other, joins], {}, 4) == 2.0 + 1.0


def test_dag_makespan_without_dependencies_is_the_longest_first_makespan():
    durations = [5.0, 3.0, 3.0, 2.0, 2.0, 2.0, 1.0]
    for workers in (1, 2, 3, 8):
        assert dag_makespan(durations, [[] for _ in durations], [int(d) for d in durations], workers) == \
            lpt_makespan(durations, workers)
