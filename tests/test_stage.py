"""The one resume engine (tiling/stage.py) the four stages share."""

from __future__ import annotations

from hollowtree.tiling.stage import Stage, params_hash
from hollowtree.tiling.store import RunStore


def test_units_done_skip_clear_and_finish(tmp_path):
    store = RunStore.create(tmp_path / "s.zarr", attrs={"schema_version": 1})
    h1, h2 = params_hash({"eps": 0.1}), params_hash({"eps": 0.2})
    stage = Stage(store, "coarse", h1, unit_stages=("coarse.blocks",))
    assert not stage.clear_if_changed()  # never completed: nothing to clear
    store.record("coarse", "0", {"params_hash": h1, "n": 5})
    store.record("coarse", "1", {"params_hash": "other"})  # an older attempt's record
    store.record("coarse.blocks", "1.0", {"params_hash": h1})
    assert set(stage.done()) == {"0"}
    assert set(stage.done("coarse.blocks")) == {"1.0"}
    assert stage.done(where=lambda v: v.get("n") == 6) == {}
    stage.finish(2, eps=0.1)
    assert store.attrs["stages"]["coarse"] == {"params_hash": h1, "units": 2, "done": 2, "eps": 0.1}
    assert not Stage(store, "coarse", h1).clear_if_changed()  # same parameters: records kept
    again = Stage(store, "coarse", h2, unit_stages=("coarse.blocks",))
    assert again.clear_if_changed()  # other parameters: every unit is redone
    assert store.records("coarse") == {}
    assert store.records("coarse.blocks") == {}
    assert again.last["params_hash"] == h1  # until the stage completes again
