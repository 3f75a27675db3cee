"""Choose ``SequenceParams.curve_min_inliers`` on training seeds.

``psi`` (tree/operators.py) fits a circle or n-gon to a node's footprint by RANSAC and
always returns its best fit, however few points it holds: on the footprint of a
colonnade and its roof slab it finds some circle through a few posts with about a tenth of
the points, a different one for every random seed, and S1 and S3 then cut along it. This
script fits ``psi`` to every ground-truth element of procedural training sites (and to each
compound: a pavilion or gateway with all its parts) with three seeds, and prints the share
of the footprint each fit holds, per class; the threshold is the largest multiple of 0.05
that keeps every fit of a dome, minaret or pillar (they have a ring by construction) and
at least 95 % of the compounds' (a pavilion's dome rim is its axis).

The threshold is chosen on the fits to the points (``refit_cells=False``). Where that fit
fails, ``psi`` fits again on the occupied cells; that second chance finds the ring of most
such elements, and on some a wrong circle through a few cells, which the threshold is there
to turn away: the second table shows the fits with the refit, and the script prints how
many ring fits it adds at or above the chosen threshold and how many of its fits fall below.

Run: ``python benchmarks/fit_curve_inliers.py --seeds 0-13 [--points 2e6]`` (training
seeds only; the scans are made under ``--work``).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from hollowtree.scenes.procedural import GENERATOR, SPLITS, scan_draw  # noqa: E402
from hollowtree.scenes.synth import synth  # noqa: E402
from hollowtree.tiling.readers import PointBlock, read_blocks  # noqa: E402
from hollowtree.tree.curves import TransportCurve  # noqa: E402
from hollowtree.tree.operators import psi, v1  # noqa: E402

RINGS = ("dome", "minaret", "pillar")
COMPOUND = re.compile(r"(.*pavilion \d+|.*gateway \d+)")
_RESULTS = REPO / "benchmarks" / "results"


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    seeds = list(range(int(a), int(b) + 1)) if b else [int(s) for s in text.split(",")]
    lo, hi = SPLITS["train"]
    if any(not lo <= s < hi for s in seeds):
        raise SystemExit(f"--seeds: only training seeds ({lo}-{hi - 1}) may choose a threshold")
    return seeds


def site_fits(scan: Path, elements: Path, repeats: int = 3, *,
              refit_cells: bool = False) -> dict[str, list[list[float]]]:
    """Per class (and ``compound``), the inlier share of ``psi`` on each element's points,
    ``repeats`` seeds each (-1: no curve)."""
    import pyarrow.parquet as pq

    b = PointBlock.concat(read_blocks(str(scan)))
    gi, xyz = np.asarray(b.extra["gt_instance"]), b.xyz
    t = pq.read_table(elements, columns=["instance", "class_name", "name"]).to_pydict()
    units: dict[tuple[str, str], list[int]] = defaultdict(list)
    for inst, cls, name in zip(t["instance"], t["class_name"], t["name"], strict=True):
        units[(cls, name)].append(inst)
        m = COMPOUND.match(name)
        if m:
            units[("compound", m.group(1))].append(inst)
    order = np.argsort(gi, kind="stable")
    sg = gi[order]
    out: dict[str, list[list[float]]] = defaultdict(list)
    for (cls, _), insts in units.items():
        idx = np.concatenate([order[np.searchsorted(sg, i):np.searchsorted(sg, i, "right")] for i in insts])
        if len(idx) < 500:
            continue
        a = xyz[idx] - xyz[idx].mean(axis=0)
        fits = [psi(v1(a), refit_cells=refit_cells, rng=np.random.default_rng(r)) for r in range(repeats)]
        out[cls].append([f.inlier_fraction if isinstance(f, TransportCurve) else -1.0 for f in fits])
    return out


def choose(fits: dict[str, list[list[float]]], *, step: float = 0.05, compounds: float = 0.95) -> float:
    """The largest multiple of ``step`` keeping every ring's fit and ``compounds`` of the
    compounds' fits (fits without a curve left out)."""
    ring = np.array([x for c in RINGS for r in fits.get(c, []) for x in r if x >= 0])
    comp = np.array([x for r in fits.get("compound", []) for x in r if x >= 0])
    best = 0.0
    for k in range(1, int(1 / step)):
        t = round(k * step, 6)
        if (ring >= t).all() and (not len(comp) or (comp >= t).mean() >= compounds):
            best = t
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-13", help="training seeds: A-B or A,B,C")
    ap.add_argument("--points", type=float, default=2e6)
    ap.add_argument("--work", type=Path, default=REPO / "out" / "curve-inliers")
    ap.add_argument("--json", type=Path, default=_RESULTS / "curve-inliers.json")
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    fits: dict[str, list[list[float]]] = defaultdict(list)
    refit: dict[str, list[list[float]]] = defaultdict(list)
    for seed in _seeds(args.seeds):
        scan = args.work / f"{GENERATOR}-{seed}.laz"
        if not scan.exists():
            d = scan_draw(seed)  # as bench_generalize and `hollowtree synth gen` scan it
            synth("gen", scan, n_points=int(args.points), seed=seed, noise=d.noise,
                  registration_error=d.registration_error)
        elements = scan.with_name(f"{GENERATOR}-{seed}.elements.parquet")
        for into, cells in ((fits, False), (refit, True)):
            for cls, rows in site_fits(scan, elements, refit_cells=cells).items():
                into[cls] += rows
        print(f"seed {seed}: {sum(len(v) for v in fits.values())} elements so far", flush=True)
    tables = {"points": _table(fits, "fits to the points"), "refit_cells": _table(refit, "with the cells' refit")}
    t = choose(fits)
    old = np.array([x for c in RINGS for r in fits.get(c, []) for x in r])
    new = np.array([x for c in RINGS for r in refit.get(c, []) for x in r])
    second = (old < 0) & (new >= 0)  # the refit's own fits
    gained, below = int((second & (new >= t)).sum()), int((second & (new < t)).sum())
    print(f"chosen curve_min_inliers: {t}; the refit adds {gained} ring fits at or above it, "
          f"{below} below")
    args.json.write_text(json.dumps({"benchmark": "fit_curve_inliers", "seeds": args.seeds, "points": args.points,
                                     "classes": tables["points"], "classes_refit_cells": tables["refit_cells"],
                                     "chosen": t, "refit_ring_fits": {"at_or_above": gained, "below": below}},
                                    indent=1) + "\n")
    return 0


def _table(fits: dict[str, list[list[float]]], title: str) -> dict[str, dict]:
    table = {}
    print(f"{title}:\n{'class':<9} {'elements':>8} {'no curve':>9} {'min':>6} {'q05':>6} {'median':>7}")
    for cls in sorted(fits):
        f = np.array(fits[cls])
        ok = f[f >= 0]
        row = {"elements": len(f), "no_curve": round(float(np.mean(f < 0)), 3),
               **({"min": round(float(ok.min()), 3), "q05": round(float(np.quantile(ok, 0.05)), 3),
                   "median": round(float(np.median(ok)), 3)} if len(ok) else {})}
        table[cls] = row
        print(f"{cls:<9} {row['elements']:>8} {row['no_curve']:>9.2f} {row.get('min', -1):>6.2f} "
              f"{row.get('q05', -1):>6.2f} {row.get('median', -1):>7.2f}")
    return table


if __name__ == "__main__":
    sys.exit(main())
