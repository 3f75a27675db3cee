"""The hierarchical tree (issue 6): operator, sequence and whole-tree times, one run.

Segments: the element-class points of synthetic scenes scanned in memory
(``scenes.sites.build_scene`` + ``scenes.scanner.scan``, as ``tests/test_tree_build.py``
makes them), randomly subsampled to ``--points`` points (default 100 000):

* ``minaret``: the minaret test scene (7 balconies), minaret-class points;
* ``curved_arcade``: the curved arcade test scene (9 arches), arch-class points;
* ``arcade``: the straight arcade test scene, arch-class points (the scan is finer so it
  holds enough points; a segment with fewer points than asked is used whole).

Per segment the script times each operator (``v1``, ``psi``, ``p``, ``u``, ``h``, ``v2``,
``rho``; ``p``, ``u``, ``v2`` and ``rho`` on the transport curve ``psi`` found), each
sequence on its own (``s1`` and ``s3`` *including* their ``psi`` fit, as a caller of one
sequence pays it) and ``propose`` (all three and the storeys, one ``psi`` shared). Every figure is the
median of ``--repeats`` runs (RANSAC seeds fixed).

Whole tree: ``build_tree`` of the minaret segment (``max_depth=3``, ``rng=0``) with

1. the tests' stand-in classifier (ground-truth majority class by nearest labelled
   point; a k-d tree query per child, so it costs about as much as a light classifier),
   the paper's energy deciding;
2. HollowNet, ``hollownet.predict.Classifier.get()`` on CPU, when
   ``hollownet/weights/hollownet-v1.pt`` exists (the output says so when it does not),
   once with the paper's energy deciding and once with the split model (the default of
   ``hollowtree run``, ``tree/data/split-v1.json``);
3. with ``--hollownet-weights PATH``, HollowNet loaded from another weights file (a
   training checkpoint, say) as well: the network and the voxelisation are the same,
   so the *time* is HollowNet's even though the classes are not final; the tree's
   shape then depends on those weights.

The classifier's own share of the time is reported apart (its calls wrapped and timed).

Targets (issue 6): under 50 ms per projection sequence on a 100 k-point segment; under
1 s for the whole tree of a 100 k-point minaret, HollowNet calls included. Ratios are
time / target (below 1 meets it). The machine has 2 shared cores: compare ratios taken
in one run.

Run: ``python benchmarks/bench_tree.py [--points 100000] [--repeats 7] [--tree-repeats 3]
[--hollownet-weights PATH] [--json OUT]`` (default ``benchmarks/results/tree.json``: seconds per
segment and step, per tree its row of the whole-tree table).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from _results import add_json, write

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from hollowtree.classes import ClassId  # noqa: E402
from hollowtree.scenes.scanner import ScanParams, scan  # noqa: E402
from hollowtree.scenes.sites import build_scene  # noqa: E402
from hollowtree.tree import build_tree  # noqa: E402
from hollowtree.tree.operators import TransportCurve, h, p, psi, rho, u, v1, v2  # noqa: E402
from hollowtree.tree.sequences import SequenceParams, propose, s1, s2, s3  # noqa: E402
from tests.test_tree_build import StandInClassifier  # noqa: E402  (the tests' stand-in for HollowNet)

SEQ_TARGET_S = 0.050
TREE_TARGET_S = 1.0
HOLLOWNET_WEIGHTS = REPO / "hollownet" / "weights" / "hollownet-v1.pt"
#: (scene, class of the segment's points, scan step in degrees)
SEGMENTS = (
    ("minaret", ClassId.MINARET, 0.17),
    ("curved_arcade", ClassId.ARCH, 0.2),
    ("arcade", ClassId.ARCH, 0.14),
)


class Timed:
    """Wraps a classifier and adds up the time spent in its ``predict``."""

    def __init__(self, inner) -> None:
        self.inner, self.seconds, self.calls, self.segments = inner, 0.0, 0, 0

    def predict(self, segments):
        t0 = time.perf_counter()
        out = self.inner.predict(segments)
        self.seconds += time.perf_counter() - t0
        self.calls += 1
        self.segments += len(segments)
        return out


def segment(name: str, cls: ClassId, step: float, n_points: int):
    """Scan ``name``; return (points of class ``cls`` subsampled to n_points, full scan xyz,
    full scan classes)."""
    chunks = list(scan(build_scene(name), ScanParams(step_deg=step, seed=0), workers=2))
    xyz = np.concatenate([c.xyz for c in chunks])
    gcls = np.concatenate([c.gt_class for c in chunks])
    pts = xyz[gcls == int(cls)]
    if len(pts) > n_points:
        pts = pts[np.sort(np.random.default_rng(0).choice(len(pts), n_points, replace=False))]
    # Local metres, as pipeline/tree_stage.py hands segments to the tree.
    origin = pts.mean(axis=0)
    return pts - origin, xyz - origin, gcls


def median_time(fn, repeats: int) -> float:
    fn()  # warm-up (imports, caches)
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def bench_segment(pts: np.ndarray, repeats: int) -> dict[str, float | str]:
    params = SequenceParams()
    xy = v1(pts)
    curve = psi(xy, rng=0)
    out: dict[str, float | str] = {"n_points": float(len(pts))}
    out["curve"] = (f"{'circle' if curve.n_sides == 0 else f'{curve.n_sides}-gon'} r={curve.radius:.2f}"
                    if isinstance(curve, TransportCurve) else "none (straight)")
    out["v1"] = median_time(lambda: v1(pts), repeats)
    out["psi"] = median_time(lambda: psi(v1(pts), rng=0), repeats)
    out["h"] = median_time(lambda: h(pts), repeats)
    t = h(pts)[:, 0]
    hist_count = v2(t)
    if isinstance(curve, TransportCurve):
        out["p"] = median_time(lambda: p(pts, curve), repeats)
        out["u"] = median_time(lambda: u(pts, curve), repeats)
        prof = p(pts, curve)
        out["v2 (max, S1)"] = median_time(lambda: v2(prof[:, 1], prof[:, 0], statistic="max"), repeats)
        hist_count = v2(u(pts, curve)[:, 0])
    out["v2 (count, S2/S3)"] = median_time(lambda: v2(t), repeats)
    out["rho"] = median_time(lambda: rho(hist_count, prominence=params.prominence), repeats)
    out["s1 (with psi)"] = median_time(lambda: s1(pts, rng=0), repeats)
    out["s2"] = median_time(lambda: s2(pts), repeats)
    out["s3 (with psi)"] = median_time(lambda: s3(pts, rng=0), repeats)
    out["propose (S1+S2+S3+storeys, one psi)"] = median_time(lambda: propose(pts, rng=0), repeats)
    return out


def bench_tree(pts: np.ndarray, classifier, repeats: int, split=None) -> dict[str, float]:
    timed = Timed(classifier)
    build_tree(pts, timed, rng=0, split=split)  # warm-up
    ts, cls_s = [], []
    for _ in range(repeats):
        timed.seconds, timed.calls, timed.segments = 0.0, 0, 0
        t0 = time.perf_counter()
        r = build_tree(pts, timed, rng=0, split=split)
        ts.append(time.perf_counter() - t0)
        cls_s.append(timed.seconds)
    return {"total": statistics.median(ts), "classifier": statistics.median(cls_s),
            "calls": timed.calls, "segments classified": timed.segments, "nodes": len(r.nodes),
            "root children": int(np.sum(r.nodes.parent == 0)),
            "root sequence": int(r.nodes.sequence[1]) if len(r.nodes) > 1 else 0}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--tree-repeats", type=int, default=3)
    ap.add_argument("--hollownet-weights", type=Path, default=None,
                    help="also time the tree with HollowNet loaded from this file (timing only)")
    add_json(ap, "tree")
    args = ap.parse_args(argv)

    report: dict = {"points": args.points, "cpus": len(os.sched_getaffinity(0)), "segments": {}, "trees": {}}
    minaret = None
    print(f"# bench_tree: {args.points} points per segment, median of {args.repeats} runs, "
          f"{report['cpus']} CPUs")
    for name, cls, step in SEGMENTS:
        pts, xyz, gcls = segment(name, cls, step, args.points)
        if name == "minaret":
            minaret = (pts, xyz, gcls)
        res = bench_segment(pts, args.repeats)
        report["segments"][name] = res
        print(f"\n## {name}: {len(pts)} points, transport curve: {res['curve']}")
        print(f"{'step':32s} {'ms':>9s} {'/ 50 ms':>8s}")
        for k, v in res.items():
            if k in ("curve", "n_points"):
                continue
            ratio = f"{v / SEQ_TARGET_S:8.2f}" if k.startswith(("s1", "s2", "s3")) else ""
            print(f"{k:32s} {1e3 * v:9.2f} {ratio}")

    assert minaret is not None
    pts, xyz, gcls = minaret
    print(f"\n## whole tree: minaret, {len(pts)} points, max_depth 3")
    print(f"{'classifier':40s} {'total s':>8s} {'/ 1 s':>6s} {'classifier s':>12s} {'calls':>6s} "
          f"{'segments':>8s} {'nodes':>6s} {'root':>10s}")
    from hollowtree.tree.split import load_split_model

    clfs: list[tuple[str, object, object]] = [("stand-in (tests), energy", StandInClassifier(xyz, gcls), None)]
    if HOLLOWNET_WEIGHTS.is_file():
        from hollowtree.hollownet.predict import Classifier
        clfs.append(("HollowNet, CPU, energy", Classifier.get(), None))
        clfs.append(("HollowNet, CPU, split model (default)", Classifier.get(), load_split_model()))
    else:
        report["trees"]["HollowNet"] = f"skipped: {HOLLOWNET_WEIGHTS.relative_to(REPO)} does not exist"
    if args.hollownet_weights is not None:
        from hollowtree.hollownet.predict import Classifier
        clfs.append((f"HollowNet ({args.hollownet_weights.name}, timing only)",
                     Classifier(args.hollownet_weights), None))
    for label, clf, split in clfs:
        r = bench_tree(pts, clf, args.tree_repeats, split)
        report["trees"][label] = r
        print(f"{label:40s} {r['total']:8.3f} {r['total'] / TREE_TARGET_S:6.2f} {r['classifier']:12.3f} "
              f"{r['calls']:6d} {r['segments classified']:8d} {r['nodes']:6d} "
              f"{r['root children']:3d} x S{r['root sequence']}")
    if not HOLLOWNET_WEIGHTS.is_file():
        print(f"HollowNet: skipped, {HOLLOWNET_WEIGHTS.relative_to(REPO)} does not exist "
              "(not trained yet); the tree time above uses the stand-in classifier only.")
    write(args.json, "bench_tree", args, **report)
    return report


if __name__ == "__main__":
    main()
