"""``hollowtree view``: time to the first view, the server's peak memory, the first view's
payload and the chunks it reads, against stores of growing point counts.

For each store, the server runs as its own process (``python -m hollowtree.pipeline.view
STORE --port 0``, what ``hollowtree view`` runs) and a client does what the page does: it
asks for ``/api/meta``, then for every node of the first-view plan (three requests at a
time, as the page), then for level 0 of every other node (what the page streams next).
Figures: seconds from starting the server to the first view's last byte (and from the
page's first request), the payload's bytes and points, the chunks the server read
(``/api/stats``: every read is counted by the chunks it touches) and the server's peak
resident memory (``VmHWM``).

Stores: the demo store (``--store``, default ``out/local.zarr`` of ``workflows/local.yaml``;
made with ``hollowtree run workflows/local.yaml`` when absent) and synthetic stores of
``--synthetic`` points (default 1 M, 10 M, 100 M) written straight into the run store's
layout (docs/store.md: tiles of ``tile_points`` points in chunks of 262 144, labels parts,
the labels stage's records with class counts) without running the pipeline, in
``--scratch`` (kept for the next run). A synthetic store has no tree tables and no
input-order label arrays: the viewer reads neither for the first view.

With playwright and Debian's chromium, the page itself is timed too: from starting the
server to the first view drawn in headless Chromium (software WebGL), a fresh server.

Run: ``python benchmarks/bench_view.py [--synthetic 1e6,1e7,1e8] [--no-browser] [--out benchmarks/results/view.json]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TILE_POINTS = 2_000_000
TILE_SIZE = 50.0
BUFFER_FRACTION = 0.04  # rows of a tile from its neighbours' cores (core = False)


def synthetic_store(path: Path, n_points: int, *, seed: int = 0) -> Path:
    """A labelled run store of ``n_points`` points in the layout the viewer reads."""
    from hollowtree.classes import NUM_CLASSES
    from hollowtree.tiling.store import RunStore

    if (path / "zarr.json").is_file() and RunStore.open(path).attrs.get("bench_complete"):
        return path
    if path.exists():
        import shutil

        shutil.rmtree(path)
    n_tiles = max(1, math.ceil(n_points / TILE_POINTS))
    nx = math.ceil(math.sqrt(n_tiles))
    ny = math.ceil(n_tiles / nx)
    scale, offset = [0.001] * 3, [500000.0, 3500000.0, 200.0]
    attrs = {
        "sources": [{"path": "synthetic", "format": "laz", "point_count": n_points,
                     "mins": [offset[0], offset[1], offset[2]],
                     "maxs": [offset[0] + nx * TILE_SIZE, offset[1] + ny * TILE_SIZE, offset[2] + 30.0]}],
        "grid": {"origin": offset[:2], "tile_size": TILE_SIZE, "buffer": 2.0, "shape": [nx, ny]},
        "coords": {"dtype": "int32", "scale": scale, "offset": offset},
        "fields": {"intensity": ["uint16", []], "rgb": ["uint16", [3]]},
        "ingest": {"params": {"tile_points": TILE_POINTS}, "params_hash": "bench", "tiles": list(range(n_tiles))},
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    store = RunStore.create(path, attrs=attrs)
    rng = np.random.default_rng(seed)
    counts = np.zeros(NUM_CLASSES, np.int64)
    sizes = np.full(n_tiles, n_points // n_tiles)
    sizes[: n_points - sizes.sum()] += 1
    for t in range(n_tiles):
        n_core = int(sizes[t])
        n = n_core + int(n_core * BUFFER_FRACTION)
        ix, iy = t % nx, t // nx
        # a courtyard's ground, a wall along two sides and domes: z by position
        xy = rng.random((n, 2)) * TILE_SIZE
        z = rng.normal(0, 0.02, n)
        wall = rng.random(n) < 0.3
        xy[wall, 0] = np.where(rng.random(int(wall.sum())) < 0.5, 2.0, TILE_SIZE - 2.0)
        z[wall] = rng.random(int(wall.sum())) * 12.0
        dome = rng.random(n) < 0.1
        v = rng.normal(size=(int(dome.sum()), 3))
        v[:, 2] = np.abs(v[:, 2])
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        xy[dome] = TILE_SIZE / 2 + 6.0 * v[:, :2]
        z[dome] = 12.0 + 6.0 * v[:, 2]
        world = np.column_stack([xy[:, 0] + ix * TILE_SIZE, xy[:, 1] + iy * TILE_SIZE, z])
        key = np.lexsort((world[:, 2] // 4, world[:, 1] // 4, world[:, 0] // 4))  # compact chunks, as Morton order
        world, wall, dome = world[key], wall[key], dome[key]
        core = np.ones(n, bool)
        core[rng.choice(n, n - n_core, replace=False)] = False
        index = np.zeros(n, np.uint64)
        index[core] = np.arange(n_core, dtype=np.uint64) * np.uint64(n_tiles) + np.uint64(t)  # spread over the input
        index[~core] = rng.integers(0, n_points, n - n_core).astype(np.uint64)
        xyz = np.round((world + np.asarray(offset) - np.asarray(offset)) / 0.001).astype(np.int32)
        cls = np.where(dome, 5, np.where(wall, 2, 1)).astype(np.uint8)
        store.write_unit(f"tiles/{t}", {
            "xyz": xyz, "index": index, "core": core,
            "rgb": (np.column_stack([cls * 20, cls * 30, 255 - cls * 25]).astype(np.uint16) * 257),
            "intensity": rng.integers(0, 65535, n).astype(np.uint16)})
        order = np.argsort(index[core])
        c = cls[core][order]
        store.write_unit(f"labels/parts/{t}/0", {
            "index": index[core][order], "class": c,
            "instance": np.where(c == 5, t * 2 + 1, np.where(c == 2, t * 2 + 2, 0)).astype(np.uint32),
            "segment": ((np.uint64(t + 1) << np.uint64(20)) | np.uint64(1)) * np.ones(n_core, np.uint64),
            "score": rng.random(n_core).astype(np.float32), "primitive": np.ones(n_core, np.uint8)})
        store.record("labels_tiles", str(t), {"params_hash": "bench-labels", "n_points": n_core, "parts": [{"n": n_core}]})
        counts += np.bincount(c, minlength=NUM_CLASSES)
        print(f"  synthetic {n_points:,}: tile {t + 1}/{n_tiles}", end="\r", flush=True)
    store.record("labels", "0", {"params_hash": "bench-labels", "n_labelled": n_points,
                                 "class_counts": counts.tolist()})
    store.update_attrs({"stages": {"labels": {"params_hash": "bench-labels", "units": 1, "done": 1}},
                        "bench_complete": True})
    print()
    return path


def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=600) as r:
        return r.read()


def _peak_rss(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return 0


def measure(store: Path) -> dict:
    """Start a server on ``store``, load the first view and then level 0 of every node."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "hollowtree.pipeline.view", str(store), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        line = proc.stdout.readline()
        m = re.search(r"http://[\d.]+:\d+/", line)
        if not m:
            raise RuntimeError(f"server did not start: {line!r} {proc.stderr.read()}")
        base = m.group(0)
        t_listen = time.perf_counter() - t0
        t1 = time.perf_counter()
        meta = json.loads(_get(base + "api/meta"))
        plan = meta["first_view"]

        def node(p: dict) -> int:
            return len(_get(f"{base}api/node?tile={p['tile']}&chunk={p['chunk']}&first=0&level={p['level']}"))

        with ThreadPoolExecutor(3) as pool:  # the page's three requests at a time
            sizes = list(pool.map(node, plan))
        t_first = time.perf_counter()
        stats_first = json.loads(_get(base + "api/stats"))
        rss_first = _peak_rss(proc.pid)
        n_first = sum(math.ceil(nd["rows"] * 2.0 ** (p["level"] - meta["levels"] + 1))
                      for p in plan for nd in meta["nodes"] if (nd["tile"], nd["chunk"]) == (p["tile"], p["chunk"]))
        seen = {(p["tile"], p["chunk"]) for p in plan}
        rest = [{"tile": nd["tile"], "chunk": nd["chunk"], "level": 0} for nd in meta["nodes"]
                if (nd["tile"], nd["chunk"]) not in seen]
        t2 = time.perf_counter()
        with ThreadPoolExecutor(3) as pool:
            rest_sizes = list(pool.map(node, rest))
        t_rest = time.perf_counter() - t2
        stats_all = json.loads(_get(base + "api/stats"))
        return {
            "store": str(store), "n_input": meta["n_input"], "tiles": len(meta["tiles"]), "nodes": len(meta["nodes"]),
            "server_listening_s": round(t_listen, 2),
            "first_view_s": round(t_first - t0, 2),
            "first_view_after_page_request_s": round(t_first - t1, 2),
            "first_view_nodes": len(plan), "first_view_tiles": len({p["tile"] for p in plan}),
            "first_view_level": plan[0]["level"] if plan else None,
            "first_view_points_about": n_first, "first_view_payload_bytes": sum(sizes),
            "first_view_chunk_reads": stats_first["chunk_reads"],
            "first_view_decompressed_bytes": stats_first["bytes_read"],
            "peak_rss_after_first_view_bytes": rss_first,
            "level0_everywhere_s": round(t_rest, 2), "level0_everywhere_payload_bytes": sum(sizes) + sum(rest_sizes),
            "level0_everywhere_chunk_reads": stats_all["chunk_reads"],
            "peak_rss_after_level0_everywhere_bytes": _peak_rss(proc.pid),
        }
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def measure_browser(store: Path) -> dict | None:
    """The same in headless Chromium (Debian's, with software WebGL): seconds from starting
    ``hollowtree view`` to the page's first view drawn; None without playwright or chromium."""
    import shutil

    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        return None
    if exe is None:
        return None
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=exe, args=[
            "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"])
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "hollowtree.pipeline.view", str(store), "--port", "0"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
        try:
            base = re.search(r"http://[\d.]+:\d+/", proc.stdout.readline()).group(0)
            page.goto(base)
            page.wait_for_function("window.hollowtreeViewer && window.hollowtreeViewer.ready", timeout=120_000)
            t = time.perf_counter() - t0
            return {"browser_first_view_s": round(t, 2),
                    "browser_points_drawn": page.evaluate("window.hollowtreeViewer.loadedCount()"),
                    "browser_peak_rss_bytes": _peak_rss(proc.pid)}
        finally:
            browser.close()
            proc.terminate()
            proc.wait(timeout=30)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--store", default=str(REPO / "out" / "local.zarr"), help="a real store (default: the demo's)")
    ap.add_argument("--synthetic", default="1e6,1e7,1e8", help="point counts of synthetic stores ('' for none)")
    ap.add_argument("--scratch", default="/tmp/hollowtree-bench-view", help="where the synthetic stores are kept")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "view.json"))
    ap.add_argument("--no-browser", action="store_true", help="skip the headless Chromium measurement")
    args = ap.parse_args()
    sys.path.insert(0, str(REPO))
    results = []
    store = Path(args.store)
    if not (store / "zarr.json").is_file() and store == REPO / "out" / "local.zarr":
        subprocess.run([sys.executable, "-m", "hollowtree", "run", "workflows/local.yaml"], cwd=REPO, check=True)
    if (store / "zarr.json").is_file():
        r = measure(store)
        r.update((None if args.no_browser else measure_browser(store)) or {})
        r["kind"] = "demo (workflows/local.yaml)"
        results.append(r)
        print(json.dumps(r))
    for text in filter(None, args.synthetic.split(",")):
        n = int(float(text))
        path = synthetic_store(Path(args.scratch) / f"synthetic-{n}.zarr", n)
        r = measure(path)
        r.update((None if args.no_browser else measure_browser(path)) or {})
        r["kind"] = "synthetic"
        results.append(r)
        print(json.dumps(r))
    out = {"machine": {"cpus": os.cpu_count()}, "results": results}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"{args.out}")
    print(f"{'store':<34} {'points':>12} {'tiles':>6} {'first view s':>13} {'payload MB':>11} {'chunk reads':>12} "
          f"{'peak RSS MB':>12} {'all L0 chunk reads':>19} {'peak RSS MB':>12} {'browser s':>10}")
    for r in results:
        print(f"{Path(r['store']).name:<34} {r['n_input']:>12,} {r['tiles']:>6} {r['first_view_s']:>13.2f} "
              f"{r['first_view_payload_bytes'] / 1e6:>11.1f} {r['first_view_chunk_reads']:>12} "
              f"{r['peak_rss_after_first_view_bytes'] / 2**20:>12.0f} {r['level0_everywhere_chunk_reads']:>19} "
              f"{r['peak_rss_after_level0_everywhere_bytes'] / 2**20:>12.0f} {r.get('browser_first_view_s', float('nan')):>10.2f}")


if __name__ == "__main__":
    main()
