"""The coarse stage's sparse-point test (``primitives.dbscan.sparse_points``) against the
plain query it replaced, side by side in one run.

Both find the rows of a mask whose 8th nearest neighbour among all points lies at least
``factor x spacing`` away, and the median of those distances. The reference builds a
balanced k-d tree and queries every masked row without a bound on one thread (the earlier
code); ``sparse_points`` builds a sliding-midpoint tree, stops each query at
the bound (dense rows end early) on every core, and queries the exact distance again
only for the sparse rows. The answers must be equal (the script checks it); the ratio
of the median times is the figure.

Data: per site, a synthetic scan of ``--points`` points (``hollowtree synth``, seed 0;
made in a temporary folder), every point a neighbour, a seeded 30 % of the rows masked
(about the share of points the coarse stage's first pass leaves unsegmented on
Derawar), spacing = ``default_eps / 3`` and factor 2 (the stage's defaults).

Run: ``python benchmarks/bench_sparse_points.py [--sites wazir_khan derawar]
[--points 1000000] [--repeats 3] [--json PATH]`` (default ``benchmarks/results/sparse-points.json``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _results import add_json, write

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))


def reference(xyz: np.ndarray, mask: np.ndarray, spacing: float, factor: float, k: int = 8
              ) -> tuple[np.ndarray, float]:
    """The earlier query: every masked row, unbounded, one thread."""
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(mask)
    d = cKDTree(xyz).query(xyz[rows], k=k + 1)[0][:, k]
    keep = d >= factor * spacing
    return rows[keep], float(np.median(d[keep])) if keep.any() else 0.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sites", nargs="+", default=["wazir_khan", "derawar"])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    add_json(ap, "sparse-points")
    args = ap.parse_args()

    import laspy

    from hollowtree.primitives.dbscan import default_eps, sparse_points
    from hollowtree.scenes.synth import synth

    print(f"machine: {os.cpu_count()} cores; {args.repeats} interleaved repeats per site")
    print("| site | points | sparse rows | reference s (median) | sparse_points s (median) | ratio | equal |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | --- |")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for site in args.sites:
            path = Path(tmp) / f"{site}.laz"
            synth(site, path, n_points=args.points, seed=0, overwrite=True)
            las = laspy.read(path)
            xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
            xyz -= xyz.mean(axis=0)
            mask = np.random.default_rng(0).random(len(xyz)) < 0.3
            spacing, factor = default_eps(xyz) / 3.0, 2.0
            t_ref, t_new = [], []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                want = reference(xyz, mask, spacing, factor)
                t_ref.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                got = sparse_points(xyz, mask, spacing, factor)
                t_new.append(time.perf_counter() - t0)
            equal = bool(np.array_equal(want[0], got[0]) and want[1] == got[1])
            r, n = float(np.median(t_ref)), float(np.median(t_new))
            rows.append({"site": site, "points": len(xyz), "sparse_rows": len(got[0]), "before_s": r, "after_s": n,
                         "ratio": n / r, "equal": equal})
            print(f"| {site} | {len(xyz):,} | {len(got[0]):,} | {r:.3f} | {n:.3f} | {n / r:.2f} | {equal} |",
                  flush=True)
    write(args.json, "bench_sparse_points", args, rows=rows)


if __name__ == "__main__":
    main()
