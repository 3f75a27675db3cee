"""HollowNet against the paper: voxelisation time, inference time per segment, accuracy.

- voxelisation of a 100 000-point scanned segment (a dome from the ``dome`` test scene),
  one segment at a time and in a batch of 64, with and without canonical yaw (the paper:
  131 ms, C++);
- inference per segment at batch 64 with the shipped weights, float32 and bfloat16
  autocast, 1 and 2 torch threads (the paper: 50 ms);
- accuracy of the shipped weights on a freshly generated held-out set (a seed never
  used in training; the paper: 99.03 % on its 7 classes).

Run: ``python benchmarks/bench_hollownet.py [--per-class 50] [--seed 777] [--json FILE]``
(default ``benchmarks/results/hollownet.json``; another machine's run as ``hollownet-<machine>.json``
adds a column to docs/benchmarks.md; ``isa`` names the CPU's vector units, ``bf16_native`` whether it
computes bfloat16 itself or emulates it).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import torch
from _results import add_json, write

from hollowtree.classes import ClassId
from hollowtree.hollownet.dataset import DatasetParams, generate_samples
from hollowtree.hollownet.model import DEFAULT_WEIGHTS, OUTPUT_CLASSES
from hollowtree.hollownet.predict import Classifier
from hollowtree.hollownet.train import confusion_matrix, format_confusion
from hollowtree.hollownet.voxels import voxelize, voxelize_batch
from hollowtree.scenes.scanner import ScanParams, scan
from hollowtree.scenes.sites import build_scene


def _best_ms(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1000 * float(np.median(times))


def dome_segment(n: int = 100_000) -> np.ndarray:
    scene = build_scene("dome", rng=0)
    chunks = list(scan(scene, ScanParams(step_deg=0.08, n_stations=4, seed=0)))
    xyz = np.concatenate([c.xyz for c in chunks])
    cls = np.concatenate([c.gt_class for c in chunks])
    dome = xyz[cls == ClassId.DOME]
    rng = np.random.default_rng(0)
    return dome[rng.choice(len(dome), n, replace=len(dome) < n)] + [512_000.0, 3_400_000.0, 200.0]


def cpu_flags() -> tuple[list[str], bool]:
    """The vector units the CPU reports (``/proc/cpuinfo``) and whether it has bfloat16 arithmetic."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return [], False
    flags = set(next((ln.split(":", 1)[1].split() for ln in text.splitlines() if ln.startswith("flags")), []))
    isa = ["AVX-512"] if "avx512f" in flags else ["AVX2"] if "avx2" in flags else []
    isa += ["AMX"] if "amx_tile" in flags else []
    return isa, bool(flags & {"avx512_bf16", "amx_bf16"})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-class", type=int, default=50, help="held-out samples per class (default 50)")
    ap.add_argument("--seed", type=int, default=777, help="held-out seed (default 777; training used 0)")
    ap.add_argument("--repeat", type=int, default=20)
    add_json(ap, "hollownet")
    args = ap.parse_args()
    isa, bf16 = cpu_flags()
    res: dict[str, object] = {"cpu_count": os.cpu_count(), "torch": torch.__version__, "isa": isa, "bf16_native": bf16}

    seg = dome_segment()
    for cy in (False, True):
        res[f"voxelize_ms_canonical_{cy}"] = _best_ms(lambda cy=cy: voxelize(seg, canonical_yaw=cy), args.repeat)
    batch = np.concatenate([seg] * 64)
    offsets = np.arange(65) * len(seg)
    res["voxelize_batch64_ms_per_segment"] = _best_ms(
        lambda: voxelize_batch(batch, offsets, canonical_yaw=True), 3) / 64

    t0 = time.perf_counter()
    held = generate_samples(DatasetParams(seed=args.seed, split="heldout", n_per_class=args.per_class,
                                          variants=2), keep_points=True)
    res["heldout_generation_s"] = time.perf_counter() - t0
    grids = held["grids"][np.arange(64) % len(held["grids"])]
    for threads in (1, 2):
        for precision in ("float32", "bfloat16"):
            clf = Classifier(DEFAULT_WEIGHTS, num_threads=threads, precision=precision)
            ms = _best_ms(lambda clf=clf: clf.predict_grids(grids), max(3, args.repeat // 4)) / 64
            res[f"inference_ms_per_segment_b64_{precision}_{threads}threads"] = ms
    index = {int(c): i for i, c in enumerate(OUTPUT_CLASSES)}
    truth = [index[int(c)] for c in held["labels"]]
    for precision in ("float32", "bfloat16"):
        clf = Classifier(DEFAULT_WEIGHTS, num_threads=2, precision=precision)
        t0 = time.perf_counter()
        pred = clf.predict(held["points"])
        res[f"predict_points_ms_per_segment_{precision}"] = 1000 * (time.perf_counter() - t0) / len(truth)
        cm = confusion_matrix(truth, [index[int(c)] for c in pred.class_id], len(OUTPUT_CLASSES))
        res[f"heldout_accuracy_{precision}"] = float(np.trace(cm) / cm.sum())
        if precision == "float32":
            res["confusion"] = cm.tolist()
            print(format_confusion(cm, [c.label for c in OUTPUT_CLASSES]))
    res["heldout_samples"] = len(truth)

    print("\n| measure | hollowtree | paper |\n| --- | --- | --- |")
    print(f"| voxelise a 100 k-point segment | {res['voxelize_ms_canonical_False']:.2f} ms "
          f"({res['voxelize_ms_canonical_True']:.2f} ms with canonical yaw; "
          f"{res['voxelize_batch64_ms_per_segment']:.2f} ms each in a batch of 64) | 131 ms |")
    for precision in ("float32", "bfloat16"):
        print(f"| inference per segment, batch 64, {precision} | "
              f"{res[f'inference_ms_per_segment_b64_{precision}_1threads']:.2f} ms (1 thread), "
              f"{res[f'inference_ms_per_segment_b64_{precision}_2threads']:.2f} ms (2 threads) | 50 ms |")
    print(f"| held-out accuracy ({len(truth)} segments, seed {args.seed}) | "
          f"{100 * res['heldout_accuracy_float32']:.2f} % (bfloat16: "
          f"{100 * res['heldout_accuracy_bfloat16']:.2f} %) | 99.03 % |")
    write(args.json, "bench_hollownet", args, **res)


if __name__ == "__main__":
    main()
