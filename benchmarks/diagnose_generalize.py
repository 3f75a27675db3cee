"""Where the elements a run missed were lost: coarse segments, the tree's cuts or the class.

For every finished store of a ``bench_generalize`` work folder (or the stores named), the
script reads each input's ground truth beside the run's labels and puts every arch, dome,
minaret and pillar in one bucket of :func:`scenes.metrics.loss_buckets`: found, tiny,
wrong class (cut out right, named wrong), leaves not grouped (cut out in pieces), coarse
fragments (no coarse segment holds half of it) or not cut out (one segment holds most of
it and nothing separated it). It prints a table per class, what the wrong classes were and
which of them the element check (tree/verify.py) made (the instance's class before and after).

Run: ``python benchmarks/diagnose_generalize.py out/generalize [--tiny 100] [--json PATH]``;
``--flips A.json B.json`` compares two such outputs of the same scans (two tile layouts);
``--density SPARSE.json ... DENSE.json`` compares outputs of the same sites scanned at
different densities (store names ``<site>-<points>.zarr``): recall over all elements and
over those with at least ``--tiny`` points in every scan (a scanner's visibility, not the
method, decides the rest). ``--posts`` adds, for each pillar not cut out, how its group's
root was split and whether :func:`tree.posts.posts` on the whole group finds it.
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
from hollowtree.scenes.metrics import LOSS_BUCKETS, VISIBLE_POINTS, false_positives, loss_buckets  # noqa: E402
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


def classes_before_check(node_key: np.ndarray, node_instance: np.ndarray, node_points: np.ndarray,
                         table_key: np.ndarray, table_class: np.ndarray) -> dict[int, int]:
    """Instance -> its class before the element check: the class most of its nodes' points had
    in the tree's batch tables (``table_*``, before the check) for the instance nodes of
    ``tree/nodes.parquet`` (``node_*``: final instance ids, after the check); ``*_key`` identify
    a node (segment, node id) in both.

    >>> classes_before_check(np.array([[1, 0], [1, 1], [2, 0]]), np.array([7, 7, 0]), np.array([10, 30, 5]),
    ...                      np.array([[1, 1], [1, 0], [2, 0]]), np.array([5, 8, 2]))
    {7: 5}
    """
    order = {tuple(k): c for k, c in zip(table_key.tolist(), table_class.tolist(), strict=True)}
    votes: dict[int, Counter] = defaultdict(Counter)
    for k, i, n in zip(node_key.tolist(), node_instance.tolist(), node_points.tolist(), strict=True):
        if i > 0 and tuple(k) in order:
            votes[int(i)][int(order[tuple(k)])] += int(n)
    return {i: v.most_common(1)[0][0] for i, v in votes.items()}


def _before_check(store: RunStore) -> dict[int, int]:
    """:func:`classes_before_check` of a store's tree (empty without one)."""
    import pyarrow as pa

    if not store.has_file("tree/nodes.parquet"):
        return {}
    nodes = store.read_table("tree/nodes.parquet")
    n_batches = len(store.attrs["stages"]["tree"]["batches"])
    t = pa.concat_tables([store.read_table(f"tree/tables/{b}.parquet") for b in range(n_batches)])

    def key(x):
        return np.column_stack([np.asarray(x.column(c).to_numpy(), dtype=np.int64) for c in ("segment", "node_id")])

    return classes_before_check(key(nodes), np.asarray(nodes.column("instance").to_numpy()),
                                np.asarray(nodes.column("n_points").to_numpy()), key(t),
                                np.asarray(t.column("class_id").to_numpy()))


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
    before = _before_check(store)
    for r in rows:
        if r["bucket"] == "wrong class":  # the instance covering most of it, and its class before the check
            ids, counts = np.unique(pi[(gi == r["instance"]) & (gc == r["class"]) & (pi > 0)], return_counts=True)
            if len(ids) and int(ids[np.argmax(counts)]) in before:
                r["before_check"] = ClassId(before[int(ids[np.argmax(counts)])]).label
        r["class"], r["predicted"] = ClassId(r["class"]).label, ClassId(r["predicted"]).label
    fps = false_positives(gc, gi, pc, pi, classes=classes)
    names = _element_names(Path(src[0]["path"]))
    for r in fps:
        r["class"], r["truth"] = ClassId(r["class"]).label, ClassId(r["truth"]).label
        r["name"] = names.get(r["instance"], "")
    return rows, fps


#: ``nodes.parquet``'s sequence ids (docs/store.md).
SEQUENCES = {1: "S1", 2: "S2", 3: "S3", 5: "gaps", 6: "parts", 7: "posts"}


def post_cover(xyz: np.ndarray, member: np.ndarray) -> tuple[float, int]:
    """The best point IoU of a post of :func:`tree.posts.posts` on ``xyz`` with the points
    ``member`` (a boolean mask), and that post's index (-1 when none is found).

    >>> rng = np.random.default_rng(0)
    >>> cols = [rng.uniform(-0.15, 0.15, (800, 3)) * [1, 1, 0] + [x, 0, 0] + rng.uniform(0, 3, (800, 1)) * [0, 0, 1]
    ...         for x in (0.0, 2.0, 4.0)]
    >>> slab = rng.uniform(0, 1, (1500, 3)) * [5.0, 1.0, 0.3] + [-0.5, -0.5, 3.0]
    >>> xyz = np.vstack(cols + [slab])
    >>> iou, j = post_cover(xyz, np.arange(len(xyz)) // 800 == 1)
    >>> round(iou, 2), j
    (1.0, 1)
    """
    return _best_post(_posts(xyz), member)


def _posts(xyz: np.ndarray) -> tuple | None:
    from hollowtree.tree.posts import posts

    return posts(xyz) if len(xyz) >= 2 else None


def _best_post(found: tuple | None, member: np.ndarray) -> tuple[float, int]:
    best, at = 0.0, -1
    for j, c in enumerate(found or ()):
        inter = int(member[c].sum())
        iou = inter / (len(c) + int(member.sum()) - inter)
        if iou > best:
            best, at = iou, j
    return best, at


def posts_store(store_path: Path, lost: list[dict]) -> list[dict]:
    """For each pillar of ``lost`` (:func:`diagnose_store`'s rows of one store) not cut out:
    its group's root class and first split (``SEQUENCES``, ``none``), the best IoU of a post
    found on the whole group (:func:`post_cover`) and HollowNet's class of that post."""
    from hollownet.predict import Classifier

    rows = [r for r in lost if r["class"] == "pillar" and r["bucket"] == "not cut out"]
    if not rows:
        return []
    store = RunStore.open(str(store_path))
    b = PointBlock.concat(read_blocks(store.attrs["sources"][0]["path"]))
    group = (store.read_slice("labels/segment", 0, len(b)) >> np.uint64(LEAF_BITS)).astype(np.int64)
    gc, gi = np.asarray(b.extra["gt_class"]), np.asarray(b.extra["gt_instance"])
    nodes = store.read_table("tree/nodes.parquet")
    seg, depth, seq, cls = (np.asarray(nodes.column(c).to_numpy()) for c in ("segment", "depth", "sequence",
                                                                              "class_id"))
    out: list[dict] = []
    found: dict[int, tuple | None] = {}
    for r in rows:
        member = (gc == int(ClassId.PILLAR)) & (gi == r["instance"])
        g = np.bincount(group[member & (group >= 0)]).argmax() if (member & (group >= 0)).any() else -1
        root = np.flatnonzero((seg == g) & (depth == 0))
        first = sorted({int(x) for x in seq[(seg == g) & (depth == 1)]})
        idx = np.flatnonzero(group == g)
        if g not in found:  # the group's posts, once for all its pillars
            found[g] = _posts(b.xyz[idx]) if g >= 0 else None
        iou, j = _best_post(found[g], member[idx])
        post_class = ""
        if j >= 0:
            post_class = ClassId(int(Classifier.get().predict([b.xyz[idx][found[g][j]]]).class_id[0])).label
        out.append({"instance": r["instance"], "points": r["points"], "group_points": len(idx),
                    "root": ClassId(int(cls[root[0]])).label if len(root) else "",
                    "first_split": "+".join(SEQUENCES.get(x, str(x)) for x in first) or "none",
                    "post_iou": round(float(iou), 3), "post_class": post_class})
    return out


def flips(a: list[dict], b: list[dict]) -> list[tuple[dict, dict]]:
    """The elements (``--json``'s ``lost`` rows of two runs of the same scans, e.g. two tile
    layouts) found in one run and not in the other, as pairs of their rows."""
    rows = {(r["store"], r["instance"]): r for r in b}
    return [(r, rows[k]) for r in a if (k := (r["store"], r["instance"])) in rows
            and (r["bucket"] == "found") != (rows[k]["bucket"] == "found")]


def _site(store: str) -> str:
    """``gen-v2-100000-10000000.zarr`` -> ``gen-v2-100000``: a store's site without its point count."""
    stem = store.removesuffix(".zarr")
    head, _, tail = stem.rpartition("-")
    return head if head and tail.isdigit() else stem


def density(runs: list[list[dict]], *, tiny: int) -> list[dict[str, int]]:
    """Recall of each run (``--json``'s ``lost`` rows of the same sites at different
    densities): ``found`` of ``elements`` (every element of any run; one a scan holds no
    point of is not found there) and ``found_visible`` of ``visible`` (elements of at least
    ``tiny`` points in every run)."""
    rows = [{(_site(r["store"]), r["instance"]): r for r in run} for run in runs]
    keys = set().union(*rows)
    visible = {k for k in keys if all(k in x and x[k]["points"] >= tiny for x in rows)}
    return [{"elements": len(keys), "found": sum(r["bucket"] == "found" for r in x.values()),
             "visible": len(visible), "found_visible": sum(x[k]["bucket"] == "found" for k in visible)}
            for x in rows]


def _read_lost(ap: argparse.ArgumentParser, flag: str, paths: list[Path]) -> list[list[dict]]:
    runs = []
    for p in paths:
        try:
            r = json.loads(p.read_text())
        except (OSError, ValueError) as e:
            ap.error(f"{flag} {p}: {e}")
        if not isinstance(r, dict) or "lost" not in r:
            ap.error(f"{flag} {p}: not a --json output of diagnose_generalize.py (no 'lost' list)")
        runs.append(r["lost"])
    return runs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", type=Path, help="a bench_generalize --work folder or stores")
    ap.add_argument("--flips", nargs=2, type=Path, metavar=("A.json", "B.json"),
                    help="compare two --json outputs of this script on the same scans: elements found "
                         "in one only")
    ap.add_argument("--density", nargs="+", type=Path, metavar="RUN.json",
                    help="compare --json outputs of this script on the same sites at different densities "
                         "(sparsest first): recall over all elements and over those of at least --tiny "
                         "points in every scan")
    ap.add_argument("--tiny", type=int, default=VISIBLE_POINTS,
                    help="elements under this many points are 'tiny' (default scenes.metrics.VISIBLE_POINTS)")
    ap.add_argument("--posts", action="store_true",
                    help="for each pillar not cut out: its group's root and first split, and the best "
                         "post tree.posts.posts finds on the whole group")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.density:
        res = density(_read_lost(ap, "--density", args.density), tiny=args.tiny)
        print(f"{'run':<40}{'all elements':>22}{f'>= {args.tiny} points in every scan':>36}")
        for p, r in zip(args.density, res, strict=True):
            a = f"{r['found']} / {r['elements']} ({100 * r['found'] / max(r['elements'], 1):.1f} %)"
            v = f"{r['found_visible']} / {r['visible']} ({100 * r['found_visible'] / max(r['visible'], 1):.1f} %)"
            print(f"{p.stem:<40}{a:>22}{v:>36}")
        if args.json:
            args.json.write_text(json.dumps({"tiny": args.tiny, "runs": [{"run": p.stem, **r} for p, r in
                                                                          zip(args.density, res, strict=True)]},
                                            indent=1) + "\n")
        return 0
    if args.flips:
        a, b = _read_lost(ap, "--flips", args.flips)
        pairs = flips(a, b)
        found = [sum(r["bucket"] == "found" for r in x) for x in (a, b)]
        print(f"elements {len(a)}; found {found[0]} and {found[1]}; found in one run only {len(pairs)} "
              f"({100 * len(pairs) / max(len(a), 1):.1f} %)")
        for (cls, x, y), n in Counter((r["class"], r["bucket"], s["bucket"]) for r, s in pairs).most_common():
            print(f"  {n:4} {cls}: {x} -> {y}")
        return 0
    if not args.paths:
        ap.error("name a work folder or stores (or --flips A.json B.json, or --density RUN.json ...)")
    stores = []
    for p in args.paths:
        stores += sorted((p / "stores").glob("*.zarr")) if (p / "stores").is_dir() else [p]
    rows, fps, post_rows = [], [], []
    for s in stores:
        lost, extra = diagnose_store(s, tiny=args.tiny)
        rows += [{"store": s.name, **r} for r in lost]
        fps += [{"store": s.name, **r} for r in extra]
        if args.posts:
            post_rows += [{"store": s.name, **r} for r in posts_store(s, lost)]
    table: dict[str, Counter] = defaultdict(Counter)
    for r in rows:
        table[r["class"]][r["bucket"]] += 1
    print(f"{'class':<9}" + "".join(f"{b:>22}" for b in LOSS_BUCKETS))
    for c, cnt in table.items():
        print(f"{c:<9}" + "".join(f"{cnt[b]:>22}" for b in LOSS_BUCKETS))
    wrong = Counter((r["class"], r["predicted"]) for r in rows if r["bucket"] == "wrong class")
    print("wrong class (truth -> predicted):", ", ".join(f"{a}->{b} {n}" for (a, b), n in wrong.most_common()))
    checked = Counter((r["class"], r["before_check"], r["predicted"]) for r in rows
                      if r["bucket"] == "wrong class" and r.get("before_check", r["predicted"]) != r["predicted"])
    print("of them made by the element check (truth: before -> after):",
          ", ".join(f"{a}: {b}->{c} {n}" for (a, b, c), n in checked.most_common()) or "none")
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
    if args.posts:
        kinds = Counter((r["root"], r["first_split"], "post" if r["post_iou"] >= 0.5 else "no post",
                         r["post_class"] if r["post_iou"] >= 0.5 else "") for r in post_rows)
        print(f"\npillars not cut out: {len(post_rows)} (root class, its first split, a post of IoU >= 0.5 "
              "on the whole group, HollowNet's class of it)")
        for (root, first, post, pc), n in kinds.most_common():
            print(f"  {n:4} {root or '?'}, {first}, {post}{', ' + pc if pc else ''}")
    if args.json:
        out = {"lost": rows, "false_positives": fps} | ({"posts": post_rows} if args.posts else {})
        args.json.write_text(json.dumps(out, indent=0) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
