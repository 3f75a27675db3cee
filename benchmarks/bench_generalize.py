"""Element recall and precision on procedural sites the pipeline never saw (issue 43).

For ``--sites`` seeds of ``--split`` (``scenes.procedural.SPLITS``; the report split is
``test``, never used to choose anything) the script scans the procedural site of each
seed (``hollowtree synth gen --seed S``: the family, its proportions, its stations, the
range noise and registration error all come from the seed; the point count is drawn
log-uniformly from ``--points``), runs the default workflow (``workflows/local.yaml``)
on it through ``hollowtree evaluate``, and reports, per element class and per family:

``tree``
    the default workflow (the learned split model deciding the tree's splits);
``energy``
    the same coarse segments with the paper's energy deciding (``tree.decision=energy``,
    HollowNet in the loop, without the element check), so users see what the paper's energy
    gives beside it;
``ransac+dbscan``
    the coarse segments alone, each classified whole by HollowNet (the baseline).

An element counts as found at IoU >= 0.5 (greedy one-to-one matching); recall is found
/ ground truth, precision matched predictions / predictions; ``gt_visible`` and
``found_visible`` count only the elements of ``scenes.metrics.VISIBLE_POINTS`` points or
more (those the scan shows). Scans are kept under
``--work`` and reused by a later run with the same arguments.

Run: ``python benchmarks/bench_generalize.py [--split test] [--sites 30] [--family F ...]
[--points 500000 2000000] [--no-energy] [--set KEY=VALUE] [--work out/generalize] [--json PATH]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from hollowtree.classes import ELEMENT_CLASSES, ClassId  # noqa: E402
from hollowtree.pipeline.coarse import COARSE_ALGORITHM  # noqa: E402
from hollowtree.pipeline.evaluate import evaluate_inputs, machine  # noqa: E402
from hollowtree.pipeline.tree_stage import TREE_ALGORITHM  # noqa: E402
from hollowtree.scenes.metrics import VISIBLE_POINTS  # noqa: E402
from hollowtree.scenes.procedural import (  # noqa: E402
    FAMILIES,
    GENERATOR,
    family_of,
    scan_draw,
    site_points,
    split_seeds,
)
from hollowtree.scenes.synth import synth  # noqa: E402
from hollowtree.tiling.grid import GRID_ALGORITHM  # noqa: E402

METHODS = {"tree": ("tree", []), "energy": ("tree", ["tree.decision=energy", "tree.verify=false"]),
           "ransac+dbscan": ("ransac+dbscan", [])}


def _element_sizes(path: Path) -> dict[str, list[int]]:
    """Points of every ground-truth element instance of a scan, per element class."""
    from hollowtree.tiling.readers import PointBlock, read_blocks

    b = PointBlock.concat(read_blocks(path))
    cls, inst = np.asarray(b.extra["gt_class"]), np.asarray(b.extra["gt_instance"]).astype(np.int64)
    out = {}
    for c in ELEMENT_CLASSES:
        _, n = np.unique(inst[(cls == int(c)) & (inst > 0)], return_counts=True)
        out[ClassId(c).label] = n.tolist()
    return out


def _table(rows: dict[str, dict[str, dict[str, int]]], title: str) -> str:
    lines = [title, f"{'method':<15}{'class':<9}{'GT':>6}{'found':>7}{'recall':>8}{'pred':>6}{'prec':>7}"]
    for method, per in rows.items():
        for name, c in per.items():
            rec = f"{100 * c['found'] / c['gt']:.1f}" if c["gt"] else "NA"
            prec = f"{100 * c['matched'] / c['pred']:.1f}" if c["pred"] else "NA"
            lines.append(f"{method:<15}{name:<9}{c['gt']:>6}{c['found']:>7}{rec:>8}{c['pred']:>6}{prec:>7}")
    return "\n".join(lines)


def pick_seeds(split: str, sites: int, skip: int = 0, families: list[str] | None = None) -> list[int]:
    """``sites`` seeds of ``split`` after its first ``skip``; with ``families``, as many of
    each family after its first ``skip``, in seed order.

    >>> pick_seeds("val", 2, 4, ["monument", "fort"])
    [100028, 100032, 100035, 100039]
    """
    return sorted(s for f in (families or [None]) for s in split_seeds(split, skip + sites, family=f)[skip:])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="test", choices=["train", "val", "test"])
    ap.add_argument("--sites", type=int, default=30)
    ap.add_argument("--family", nargs="+", choices=FAMILIES, default=None, metavar="F",
                    help="only these families' seeds of the split: --sites and --skip count per family")
    ap.add_argument("--skip", type=int, default=0, metavar="K",
                    help="leave out the split's first K seeds (test seeds already read: report on fresh ones)")
    ap.add_argument("--points", type=float, nargs=2, default=(5e5, 2e6), metavar=("MIN", "MAX"))
    ap.add_argument("--no-energy", action="store_true", help="skip the paper's energy path")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="a workflow override for every run (e.g. tree.split_model=PATH), repeatable")
    ap.add_argument("--work", type=Path, default=REPO / "out" / "generalize")
    ap.add_argument("--json", type=Path, default=None, help="default benchmarks/results/generalize-<split>.json")
    args = ap.parse_args(argv)
    if args.sites < 1 or args.skip < 0 or not 0 < args.points[0] <= args.points[1]:
        ap.error("--sites must be positive, --skip at least 0 and --points MIN MAX with 0 < MIN <= MAX")
    seeds = pick_seeds(args.split, args.sites, args.skip, args.family)
    args.work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    scans = []
    for seed in seeds:
        n = site_points(seed, *args.points)
        path = args.work / f"{GENERATOR}-{seed}-{n}.laz"
        if not path.exists():
            d = scan_draw(seed)
            res = synth("gen", path, n_points=n, seed=seed, noise=d.noise, registration_error=d.registration_error)
            print(f"scan {path.name}: {family_of(seed)}, {res.n_points:,} points, noise {d.noise * 1000:.1f} mm, "
                  f"registration {d.registration_error * 1000:.1f} mm", flush=True)
        scans.append(path)
    t_scan = time.perf_counter() - t0
    runs = {"tree": []} if args.no_energy else {"tree": [], "energy": []}
    for key in runs:
        _, overrides = METHODS[key]
        results, _ = evaluate_inputs([str(p) for p in scans], overrides=[*args.overrides, *overrides], store_dir=str(args.work / "stores"),
                                     json_path=args.work / f"evaluate-{key}.json", png_dir=args.work / f"png-{key}",
                                     progress=False, say=lambda _line: None)
        runs[key] = results
        print(f"{key}: {len(results)} sites evaluated ({time.perf_counter() - t0:.0f} s so far)", flush=True)
    # per method, per class (and per family): GT, found, predictions, matched predictions
    total: dict[str, dict[str, dict[str, int]]] = {}
    fam: dict[str, dict[str, dict[str, dict[str, int]]]] = defaultdict(dict)
    sites = []
    for label, (key, method) in (("tree", ("tree", "tree")), ("energy", ("energy", "tree")),
                                 ("ransac+dbscan", ("tree", "ransac+dbscan"))):
        if key not in runs:
            continue
        total[label] = {ClassId(c).label: {"gt": 0, "found": 0, "pred": 0, "matched": 0} for c in ELEMENT_CLASSES}
        for seed, r in zip(seeds, runs[key], strict=True):
            f = family_of(seed)
            fam[f].setdefault(label, {ClassId(c).label: {"gt": 0, "found": 0, "pred": 0, "matched": 0}
                                      for c in ELEMENT_CLASSES})
            for c in ELEMENT_CLASSES:
                s = r.methods[method].score(int(c))
                for bucket in (total[label][s.name], fam[f][label][s.name]):
                    bucket["gt"] += s.n_gt
                    bucket["found"] += s.n_found
                    bucket["pred"] += s.n_pred
                    bucket["matched"] += s.n_pred_matched
                    if s.n_gt_visible is not None:  # elements of VISIBLE_POINTS points or more
                        bucket["gt_visible"] = bucket.get("gt_visible", 0) + s.n_gt_visible
                        bucket["found_visible"] = bucket.get("found_visible", 0) + s.n_found_visible
            if label == "tree":
                scores = [r.methods[method].score(int(c)) for c in ELEMENT_CLASSES]
                sites.append({"seed": seed, "family": f, "input": r.input, "n_points": r.n_points,
                              "pipeline_seconds": r.pipeline_seconds,
                              "totals": {s.name: {"gt": s.n_gt, "found": s.n_found, "pred": s.n_pred,
                                                  "matched": s.n_pred_matched} for s in scores}})
    print(_table(total, f"{args.split} split, {len(seeds)} sites ({', '.join(sorted({family_of(s) for s in seeds}))})"))
    # How visible the ground-truth elements are: an element of fewer points than the
    # default workflow's free_min_points (200) can only be found inside a larger segment.
    sizes: dict[str, list[int]] = defaultdict(list)
    for p in scans:
        for name, n in _element_sizes(p).items():
            sizes[name] += n
    visibility = {name: {"elements": len(n), "median_points": int(np.median(n)) if n else 0,
                         "under_200": int(np.sum(np.asarray(n) < 200)), "under_1000": int(np.sum(np.asarray(n) < 1000))}
                  for name, n in sizes.items()}
    print(f"{'class':<9}{'elements':>9}{'median pts':>11}{'< 200 pts':>10}{'< 1000 pts':>11}")
    for name, v in visibility.items():
        print(f"{name:<9}{v['elements']:>9}{v['median_points']:>11}{v['under_200']:>10}{v['under_1000']:>11}")
    for f in sorted(fam):
        print(_table(fam[f], f"family {f}"))
    all_found = {m: (sum(c["found"] for c in per.values()), sum(c["gt"] for c in per.values()),
                     sum(c["matched"] for c in per.values()), sum(c["pred"] for c in per.values()))
                 for m, per in total.items()}
    for m, (fd, gt, mt, pr) in all_found.items():
        vis = [c for c in total[m].values() if "gt_visible" in c]
        fv, gv = sum(c["found_visible"] for c in vis), sum(c["gt_visible"] for c in vis)
        print(f"{m}: {fd} of {gt} elements found ({100 * fd / max(gt, 1):.1f} %), precision "
              f"{100 * mt / max(pr, 1):.1f} %; of those of {VISIBLE_POINTS} points or more, {fv} of {gv} "
              f"({100 * fv / max(gv, 1):.1f} %)")
    wall = time.perf_counter() - t0
    print(f"{wall:.0f} s ({t_scan:.0f} s of scanning)")
    out = args.json or REPO / "benchmarks" / "results" / f"generalize-{args.split}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"benchmark": "bench_generalize", "split": args.split, "family": args.family,
                               "overrides": args.overrides,
                               "generator": GENERATOR, "seeds": seeds, "points": list(args.points), "workflow": "workflows/local.yaml",
                               "tree_algorithm": TREE_ALGORITHM, "coarse_algorithm": COARSE_ALGORITHM,
                               "grid_algorithm": GRID_ALGORITHM, "totals": total, "families": fam, "visibility": visibility, "sites": sites,
                               "seconds": round(wall, 1), "machine": machine()},
                              indent=1) + "\n")
    print(f"results: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
