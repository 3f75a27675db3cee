"""Where the elements a run missed were lost: coarse segments, the tree's cuts or the class.

For every finished store of a ``bench_generalize`` work folder (or the stores named), the
script reads each input's ground truth beside the run's labels and puts every arch, dome,
minaret and pillar in one bucket of :func:`scenes.metrics.loss_buckets`: found, tiny,
wrong class (cut out right, named wrong), leaves not grouped (cut out in pieces), coarse
fragments (no coarse segment holds half of it) or not cut out (one segment holds most of
it and nothing separated it). It prints a table per class and what the wrong classes were.

Run: ``python benchmarks/diagnose_generalize.py out/generalize [--tiny 100] [--json PATH]``;
``--flips A.json B.json`` compares two such outputs of the same scans (two tile layouts).
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
from hollowtree.scenes.metrics import LOSS_BUCKETS, false_positives, loss_buckets  # noqa: E402
from hollowtree.tiling.readers import PointBlock, read_blocks  # noqa: E402
from hollowtree.tiling.store import RunStore  # noqa: E402


def _element_names(scan: Path) -> dict[int, str]:
    """Instance -> name from the ``<stem>.elements.parquet`` beside a generated scan (empty if none)."""
    table = scan.with_name(scan.name.split(".")[0] + ".elements.parquet")
    if not table.is_file():
        return {}
    import pyarrow.parquet as pq

    t = pq.read_table(table, columns=["instance", "name"]).to_pydict()
    return dict(zip(t["instance"], t["name"], strict=True))


def diagnose_store(store_path: Path, *, tiny: int) -> tuple[list[dict], list[dict]]:
    """:func:`scenes.metrics.loss_buckets` and :func:`scenes.metrics.false_positives` of one store."""
    store = RunStore.open(str(store_path))
    src = store.attrs["sources"]
    if len(src) != 1:
        raise SystemExit(f"{store_path}: one input per store expected")
    b = PointBlock.concat(read_blocks(src[0]["path"]))
    n = len(b)
    seg = store.read_slice("labels/segment", 0, n)
    gc, gi = np.asarray(b.extra["gt_class"]), np.asarray(b.extra["gt_instance"])
    pc, pi = store.read_slice("labels/class", 0, n), store.read_slice("labels/instance", 0, n)
    classes = tuple(int(c) for c in ELEMENT_CLASSES)
    rows = loss_buckets(gc, gi, pc, pi, (seg >> np.uint64(LEAF_BITS)).astype(np.int64), seg.astype(np.int64),
                        classes=classes, tiny=tiny)
    for r in rows:
        r["class"], r["predicted"] = ClassId(r["class"]).label, ClassId(r["predicted"]).label
    fps = false_positives(gc, gi, pc, pi, classes=classes)
    names = _element_names(Path(src[0]["path"]))
    for r in fps:
        r["class"], r["truth"] = ClassId(r["class"]).label, ClassId(r["truth"]).label
        r["name"] = names.get(r["instance"], "")
    return rows, fps


def flips(a: list[dict], b: list[dict]) -> list[tuple[dict, dict]]:
    """The elements (``--json``'s ``lost`` rows of two runs of the same scans, e.g. two tile
    layouts) found in one run and not in the other, as pairs of their rows."""
    rows = {(r["store"], r["instance"]): r for r in b}
    return [(r, rows[k]) for r in a if (k := (r["store"], r["instance"])) in rows
            and (r["bucket"] == "found") != (rows[k]["bucket"] == "found")]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", type=Path, help="a bench_generalize --work folder or stores")
    ap.add_argument("--flips", nargs=2, type=Path, metavar=("A.json", "B.json"),
                    help="compare two --json outputs of this script on the same scans: elements found "
                         "in one only")
    ap.add_argument("--tiny", type=int, default=100, help="elements under this many points are 'tiny'")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.flips:
        runs = [json.loads(p.read_text()) for p in args.flips]
        for p, r in zip(args.flips, runs, strict=True):
            if not isinstance(r, dict) or "lost" not in r:
                ap.error(f"--flips {p}: not a --json output of diagnose_generalize.py (no 'lost' list)")
        a, b = (r["lost"] for r in runs)
        pairs = flips(a, b)
        found = [sum(r["bucket"] == "found" for r in x) for x in (a, b)]
        print(f"elements {len(a)}; found {found[0]} and {found[1]}; found in one run only {len(pairs)} "
              f"({100 * len(pairs) / max(len(a), 1):.1f} %)")
        for (cls, x, y), n in Counter((r["class"], r["bucket"], s["bucket"]) for r, s in pairs).most_common():
            print(f"  {n:4} {cls}: {x} -> {y}")
        return 0
    if not args.paths:
        ap.error("name a work folder or stores (or --flips A.json B.json)")
    stores = []
    for p in args.paths:
        stores += sorted((p / "stores").glob("*.zarr")) if (p / "stores").is_dir() else [p]
    rows, fps = [], []
    for s in stores:
        lost, extra = diagnose_store(s, tiny=args.tiny)
        rows += [{"store": s.name, **r} for r in lost]
        fps += [{"store": s.name, **r} for r in extra]
    table: dict[str, Counter] = defaultdict(Counter)
    for r in rows:
        table[r["class"]][r["bucket"]] += 1
    print(f"{'class':<9}" + "".join(f"{b:>22}" for b in LOSS_BUCKETS))
    for c, cnt in table.items():
        print(f"{c:<9}" + "".join(f"{cnt[b]:>22}" for b in LOSS_BUCKETS))
    wrong = Counter((r["class"], r["predicted"]) for r in rows if r["bucket"] == "wrong class")
    print("wrong class (truth -> predicted):", ", ".join(f"{a}->{b} {n}" for (a, b), n in wrong.most_common()))
    kinds = ("piece", "other element", "no element", "mixed")
    fp_table: dict[str, Counter] = defaultdict(Counter)
    for r in fps:
        fp_table[r["class"]][r["kind"]] += 1
    print("\nfalse positives (predictions matching no element of their class)")
    print(f"{'class':<9}" + "".join(f"{k:>16}" for k in kinds))
    for c, cnt in fp_table.items():
        print(f"{c:<9}" + "".join(f"{cnt[k]:>16}" for k in kinds))
    what = Counter((r["class"], r["kind"], r["truth"]) for r in fps)
    print("false positives (predicted, kind, truth of most points):",
          ", ".join(f"{a}/{k}/{t} {n}" for (a, k, t), n in what.most_common()))
    if args.json:
        args.json.write_text(json.dumps({"lost": rows, "false_positives": fps}, indent=0) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
