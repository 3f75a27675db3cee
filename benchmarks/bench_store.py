"""Requests and time to write a run store's units on an object store (a local moto S3
server) and in a local folder, side by side in one run: Zarr's own ``create_array`` (what ``RunStore`` called
before its own writer) against ``RunStore.write_unit`` (one metadata object per array).

Each unit is a labels part, ``labels/parts/<tile>/<part>``: eight arrays of ``--rows``
rows, the same for both ways. The requests are those the server answered (one line of its
log each). The moto server runs on this machine, so its time per request is far below a
real object store's (tens of milliseconds): the request count is the figure that carries.

Run: ``python benchmarks/bench_store.py [--units 24] [--rows 20000] [--json PATH]`` (default
``benchmarks/results/store.json``). Needs the dev
dependencies ``moto[server]`` and ``s3fs``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _results import add_json
from _results import write as write_json

NAMES = ("class", "segment", "instance", "primitive", "leaf", "node", "group", "score")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=24)
    ap.add_argument("--rows", type=int, default=20_000)
    add_json(ap, "store")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from hollowtree.tiling.store import _COMPRESSOR, CHUNK_POINTS, RunStore
    from tests.moto_s3 import moto_server

    log = Path(tempfile.mkdtemp()) / "moto.log"
    with moto_server(log) as aws:
        os.environ.update(aws)
        import s3fs

        s3fs.S3FileSystem().mkdir("bench")
        rng = np.random.default_rng(0)
        units = [{k: rng.integers(0, 1000, args.rows).astype(np.uint32) for k in NAMES} for _ in range(args.units)]

        def requests() -> int:
            return sum(1 for line in log.read_text().splitlines() if '" 20' in line or '" 40' in line)

        def zarr_way(store: RunStore, group: str, arrays: dict[str, np.ndarray]) -> None:
            g = store._require_group(group)
            for name, values in arrays.items():
                arr = g.create_array(name, shape=values.shape, dtype=values.dtype, chunks=(CHUNK_POINTS,),
                                     compressors=_COMPRESSOR, overwrite=True)
                arr[...] = values

        local = Path(tempfile.mkdtemp())
        rows = []
        for where, base in (("moto S3", "s3://bench"), ("local folder", str(local))):
            for way, write in (("zarr create_array", zarr_way), ("RunStore.write_unit", RunStore.write_unit)):
                url = f"{base}/{way.split()[0].lower()}.zarr"
                store = RunStore.create(url, attrs={})
                before, t0 = requests(), time.perf_counter()
                for i, arrays in enumerate(units):
                    write(store, f"labels/parts/{i // 4}/{i % 4}", arrays)
                seconds, n = time.perf_counter() - t0, requests() - before
                back = RunStore.open(url).read_unit(f"labels/parts/{(args.units - 1) // 4}/{(args.units - 1) % 4}")
                assert all(np.array_equal(back[k], units[-1][k]) for k in NAMES), way
                rows.append((where, way, n, seconds))
        shutil.rmtree(local)
    print(f"{args.units} units of {len(NAMES)} arrays x {args.rows:,} rows")
    print(f"{'store':13s} {'way':22s} {'requests':>9s} {'per array':>10s} {'s':>7s}")
    for where, way, n, seconds in rows:
        count = f"{n:9,d} {n / (args.units * len(NAMES)):10.1f}" if where == "moto S3" else f"{'-':>9s} {'-':>10s}"
        print(f"{where:13s} {way:22s} {count} {seconds:7.2f}")
    (_, _, n0, s0), (_, _, n1, s1), (_, _, _, l0), (_, _, _, l1) = rows
    print(f"write_unit / zarr: S3 requests {n1 / n0:.2f}, S3 time {s1 / s0:.2f}, local time {l1 / l0:.2f}")
    arrays = args.units * len(NAMES)
    s3 = lambda where, v: v if where == "moto S3" else None  # noqa: E731
    write_json(args.json, "bench_store", args,
               rows=[{"store": where, "way": way, "requests": s3(where, n), "per_array": s3(where, n / arrays),
                      "s": seconds} for where, way, n, seconds in rows],
               ratios={"s3_requests": n1 / n0, "s3_time": s1 / s0, "local_time": l1 / l0})


if __name__ == "__main__":
    main()
