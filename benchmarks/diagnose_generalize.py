"""Where the elements a run missed were lost: coarse segments, the tree's cuts or the class.

For every finished store of a ``bench_generalize`` work folder (or the stores named), the
script reads each input's ground truth beside the run's labels and puts every arch, dome,
minaret and pillar in one bucket of :func:`scenes.metrics.loss_buckets`: found, tiny,
wrong class (cut out right, named wrong), leaves not grouped (cut out in pieces), coarse
fragments (no coarse segment holds half of it) or not cut out (one segment holds most of
it and nothing separated it). It prints a table per class and what the wrong classes were.

Run: ``python benchmarks/diagnose_generalize.py out/generalize [--tiny 100] [--json PATH]``.
A tool for the validation split: reading it on test seeds to choose anything breaks the
protocol of docs/generalize.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter, defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from hollowtree.classes import ELEMENT_CLASSES, ClassId  # noqa: E402
from hollowtree.pipeline.labels import LEAF_BITS  # noqa: E402
from hollowtree.scenes.metrics import LOSS_BUCKETS, loss_buckets  # noqa: E402
from hollowtree.tiling.readers import PointBlock, read_blocks  # noqa: E402
from hollowtree.tiling.store import RunStore  # noqa: E402


def diagnose_store(store_path: Path, *, tiny: int) -> list[dict]:
    """:func:`scenes.metrics.loss_buckets` of one finished store against its input's ground truth."""
    store = RunStore.open(str(store_path))
    src = store.attrs["sources"]
    if len(src) != 1:
        raise SystemExit(f"{store_path}: one input per store expected")
    b = PointBlock.concat(read_blocks(src[0]["path"]))
    n = len(b)
    seg = store.read_slice("labels/segment", 0, n)
    rows = loss_buckets(np.asarray(b.extra["gt_class"]), np.asarray(b.extra["gt_instance"]),
                        store.read_slice("labels/class", 0, n), store.read_slice("labels/instance", 0, n),
                        (seg >> np.uint64(LEAF_BITS)).astype(np.int64), seg.astype(np.int64),
                        classes=tuple(int(c) for c in ELEMENT_CLASSES), tiny=tiny)
    for r in rows:
        r["class"], r["predicted"] = ClassId(r["class"]).label, ClassId(r["predicted"]).label
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="+", type=Path, help="a bench_generalize --work folder or stores")
    ap.add_argument("--tiny", type=int, default=100, help="elements under this many points are 'tiny'")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    stores = []
    for p in args.paths:
        stores += sorted((p / "stores").glob("*.zarr")) if (p / "stores").is_dir() else [p]
    rows = []
    for s in stores:
        for r in diagnose_store(s, tiny=args.tiny):
            rows.append({"store": s.name, **r})
    table: dict[str, Counter] = defaultdict(Counter)
    for r in rows:
        table[r["class"]][r["bucket"]] += 1
    print(f"{'class':<9}" + "".join(f"{b:>22}" for b in LOSS_BUCKETS))
    for c, cnt in table.items():
        print(f"{c:<9}" + "".join(f"{cnt[b]:>22}" for b in LOSS_BUCKETS))
    wrong = Counter((r["class"], r["predicted"]) for r in rows if r["bucket"] == "wrong class")
    print("wrong class (truth -> predicted):", ", ".join(f"{a}->{b} {n}" for (a, b), n in wrong.most_common()))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=0) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
