"""The resume protocol every stage shares: one engine for ingest, coarse, tree and labels.

A stage's parameters (and the hash of the stage it reads) hash to ``params_hash``. Each
unit of work (a map chunk, a tile, a block, a batch, a range) writes its data, then a
completion record that carries that hash (``RunStore.record``). A rerun:

1. compares the hash with the one the stage recorded when it last completed; another
   hash clears the stage's unit records (every unit is redone);
2. skips the units recorded with this hash and runs the rest;
3. writes the stage's attributes (``stages.<name>``: hash, units, done, and what the
   stage adds) when every unit is recorded.

Which parameters go into the hash, and what a stage does with its records, stay with
the stage.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from typing import Any

from hollowtree.tiling.store import RunStore

__all__ = ["Stage", "params_hash"]


def params_hash(value: Any) -> str:
    """The 16-hex-digit hash of a JSON value (dict keys sorted).

    >>> params_hash({"b": 1, "a": [2, 3]}) == params_hash({"a": [2, 3], "b": 1})
    True
    >>> len(params_hash(["labels-v3", "abc", True]))
    16
    """
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()[:16]


class Stage:
    """One stage of one store, under one ``params_hash``.

    Parameters
    ----------
    store : RunStore
        Opened for writing.
    name : str
        The stage (``stages.<name>`` in the store's attributes; its units' records).
    params_hash : str
    unit_stages : sequence of str
        Further record groups the stage's units write (a coarse tile's blocks, the labels'
        tiles); cleared with the stage's own.
    """

    def __init__(self, store: RunStore, name: str, params_hash: str, *, unit_stages: Sequence[str] = ()) -> None:
        self.store, self.name, self.hash = store, name, params_hash
        self.unit_stages = (name, *unit_stages)

    @property
    def last(self) -> dict[str, Any]:
        """What the stage recorded when it last completed (empty if it never did)."""
        return dict(self.store.attrs.get("stages", {}).get(self.name, {}))

    def clear_if_changed(self) -> bool:
        """Clear every unit record when the stage last completed under another hash."""
        if self.last.get("params_hash") not in (None, self.hash):
            for s in self.unit_stages:
                self.store.clear_records(s)
            return True
        return False

    def done(self, unit_stage: str | None = None,
             where: Callable[[dict[str, Any]], bool] | None = None) -> dict[str, dict[str, Any]]:
        """The records of the units done under this hash (of ``unit_stage``, default the
        stage's own), by unit name."""
        recs = self.store.records(unit_stage or self.name)
        return {k: v for k, v in recs.items() if v.get("params_hash") == self.hash and (where is None or where(v))}

    def finish(self, units: int, **extra: Any) -> None:
        """Record the stage complete: its hash, ``units`` done of ``units``, and ``extra``."""
        self.store.update_attrs({"stages": {**self.store.attrs.get("stages", {}), self.name: {
            "params_hash": self.hash, "units": units, "done": units, **extra}}})
