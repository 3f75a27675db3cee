"""The generated tables of the docs: from ``benchmarks/results/*.json`` and the workflow schema.

A generated table sits in a Markdown file between two comments::

    <!-- generated: NAME -->
    ... (rewritten by this script; do not edit by hand)
    <!-- end generated -->

``NAME`` is a key of :data:`GENERATORS`. The script reads README.md and every ``.md``
under ``docs/``, replaces the text between each pair with what the generator gives now,
and writes the files that changed. With ``--check`` it writes nothing, names every block
that is out of date and exits 1 (``tests/test_docs_generated.py`` runs it).

Run: ``python benchmarks/report.py [--check]``. When a newer run is checked in under
``benchmarks/results/``, name its file in :data:`LATEST` (or let the globbed tables pick it
up) and run the script again.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO / "benchmarks") not in sys.path:
    sys.path.insert(0, str(REPO / "benchmarks"))

from choose import f1 as _f1  # noqa: E402
from results_md import spread_table, table1  # noqa: E402

RESULTS = REPO / "benchmarks" / "results"

#: The latest run of each kind of element-recall result (``bench_generalize.py --json``).
#: These are the figures of docs/generalize.md; edit the file names when a newer run replaces one.
LATEST = {
    "test": "generalize-test-tree-v47.json",
    "test-5m": "generalize-test-5m-gen-v3.json",
    "val-4m": "generalize-val-4m-tree-v47.json",
    "val-1m": "generalize-val-density-1m-tree-v47.json",
    "val-10m": "generalize-val-density-10m-tree-v47.json",
    "val-3m": "generalize-val-density-3m-tree-v47.json",
    # the second validation batch (seeds 100 014-100 027) at the hidden scenes' density
    "val-5m-b": "generalize-val-5m-b-tree-v39.json",
    # the dome batch: the next 6 validation seeds of each family with domes (100 028-100 068)
    "val-domes": "generalize-val-domes-tree-v47.json",
    # diagnose_generalize.py --density over the 1 M, 3 M and 10 M rows (tree seed 0)
    "density": "generalize-val-density-visible-tree-v47.json",
    "val": "generalize-val-tree-v47.json",
    # the latest run with the paper's energy path (other runs pass --no-energy; it runs with
    # tree.verify=false, so tree-v25 and tree-v26 did not change it)
    "test-energy": "generalize-test-tree-v47.json",
    # docs/results.md: the paper's five sites, a report set (hollowtree evaluate --seeds 3)
    "five-sites": "five-sites-10m-tree-v39.json",
}

#: Variants judged on tree seeds 0, 1 and 2 (the selection rule from ``tree-v36``,
#: docs/generalize.md): the name part of their JSONs (``generalize-val-4m-<name>.json`` is
#: seed 0, ``...-<name>-seed1.json`` seed 1, ...), in the order they were run.
VAL_SEEDS = {
    "tree-v42": "`tree-v42`: arcade rows along circles, cells that partition a row",
    "rerun-v42": "`tree-v42` again, a fresh install at the versions of `constraints.txt` (`choose.py`)",
    "tree-v45": "`tree-v45`: a band's ends from its plateau's median",
    "tree-v47": "`tree-v47`: a frame's small pieces go whole by height (default)",
}
ELEMENTS = ("arch", "dome", "minaret", "pillar")
BEGIN = re.compile(r"<!-- generated: ([\w.-]+) -->\n")
END = "<!-- end generated -->"


def _load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def _pct(a: float, b: float) -> str:
    return f"{100 * a / b:.1f} %" if b else "NA"


def _n(x: int) -> str:
    """An integer with thin groups of three: 1 000 066."""
    return f"{x:,}".replace(",", " ")


def _mega(n: float) -> str:
    return f"{n / 1e6:g} M"


def _sum(counts: dict[str, dict[str, int]], key: str) -> int:
    return sum(counts[c][key] for c in ELEMENTS if c in counts)


def _found(counts: dict[str, dict[str, int]]) -> tuple[int, int, int, int]:
    return _sum(counts, "found"), _sum(counts, "gt"), _sum(counts, "matched"), _sum(counts, "pred")


def _points(d: dict) -> str:
    lo, hi = d["points"]
    return _mega(lo) if lo == hi else f"{_mega(lo)[:-2]}-{_mega(hi)}"


def _code(d: dict) -> str:
    """The tree's label a run carried, the coarse stage's and the grid's where they were
    recorded (runs before ``grid-v2`` carry no grid label), and the procedural sites'
    generator (``gen-v1`` before it was recorded)."""
    labels = [d[k] for k in ("tree_algorithm", "coarse_algorithm", "grid_algorithm") if k in d]
    if d.get("benchmark") == "bench_generalize":
        labels.append(d.get("generator", "gen-v1"))
    return ", ".join(f"`{x}`" for x in labels) or "?"


def _seeds(d: dict) -> str:
    s = d["seeds"]
    return f"{len(s)} ({_n(s[0])}-{_n(s[-1])})"


# --- docs/generalize.md ------------------------------------------------------------------

def generalize_figures() -> str:
    """The headline of issue 43: found and precision per split and density."""
    rows = [("test", "test split"), ("test-5m", "test split, 5 M points"),
            ("val", "validation"), ("val-4m", "validation, 4 M points"), ("val-1m", "validation, 1 M points"),
            ("val-3m", "validation, 3 M points"), ("val-10m", "validation, 10 M points"),
            ("val-5m-b", "validation, second batch, 5 M points"),
            ("val-domes", "validation, dome batch (4 families)")]
    out = ["| sites | seeds | points per site | code | arch | dome | minaret | pillar | all found | precision "
           "| found, 100 points or more | source |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for key, label in rows:
        d = _load(LATEST[key])
        t = d["totals"]["tree"]
        fd, gt, m, p = _found(t)
        per = [f"{t[c]['found']} / {t[c]['gt']}" for c in ELEMENTS]
        vis = "-"  # runs before the visible elements were counted
        if all("gt_visible" in t[c] for c in ELEMENTS):
            fv, gv = _sum(t, "found_visible"), _sum(t, "gt_visible")
            vis = f"{fv} / {gv} ({_pct(fv, gv)})"
        out.append(f"| {label} | {_seeds(d)} | {_points(d)} | {_code(d)} | " + " | ".join(per)
                   + f" | **{fd} / {gt} ({_pct(fd, gt)})** | **{_pct(m, p)}** | {vis} | `{LATEST[key]}` |")
    return "\n".join(out)


def density() -> str:
    """Recall of the same validation sites at 1 M, 3 M and 10 M points, over every element
    and over those a scan of each density shows with at least ``tiny`` points."""
    d = _load(LATEST["density"])
    out = [f"| run | all elements | at least {d['tiny']} points in every scan |", "| --- | --- | --- |"]
    for r in d["runs"]:
        out.append(f"| `{r['run']}` | {r['found']} / {r['elements']} ({_pct(r['found'], r['elements'])}) | "
                   f"{r['found_visible']} / {r['visible']} ({_pct(r['found_visible'], r['visible'])}) |")
    return "\n".join(out)


# --- docs/benchmarks.md ------------------------------------------------------------------

def generalize_test() -> str:
    """Per class: the default, the paper's energy and the coarse segments on the test split."""
    d, e = _load(LATEST["test"]), _load(LATEST["test-energy"])
    rows = [("default (split model)", d["totals"]["tree"], d, LATEST["test"]),
            ("coarse segments, each classified whole", d["totals"]["ransac+dbscan"], d, LATEST["test"]),
            ("paper's energy", e["totals"]["energy"], e, LATEST["test-energy"])]
    out = ["| method | code | arch | dome | minaret | pillar | all | precision | source |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, t, src, f in rows:
        fd, gt, m, p = _found(t)
        per = [f"{t[c]['found']} / {t[c]['gt']}" for c in ELEMENTS]
        out.append(f"| {name} | {_code(src)} | " + " | ".join(per)
                   + f" | {fd} / {gt} ({_pct(fd, gt)}) | {_pct(m, p)} | `{f}` |")
    fams = []
    for fam, v in d["families"].items():
        fd, gt, _, _ = _found(v["tree"])
        fams.append((fd / gt if gt else 0, f"{fam.replace('_', ' ')} {fd} / {gt} ({_pct(fd, gt)})"))
    out += ["", "Per family (default): " + ", ".join(s for _, s in sorted(fams, reverse=True)) + "."]
    out += ["", "| class | elements | median points | under 200 | under 1 000 |", "| --- | --- | --- | --- | --- |"]
    for c, v in d.get("visibility", {}).items():
        out.append(f"| {c} | {v['elements']} | {_n(v['median_points'])} | {v['under_200']} | {v['under_1000']} |")
    return "\n".join(out)


def small() -> str:
    d = _load("small.json")
    out = ["| scan | points | cluster | in process | cluster / in process |", "| --- | ---: | ---: | ---: | ---: |"]
    for r in d["rows"]:
        out.append(f"| `{r['scan']}` | {_n(r['points'])} | {r['cluster_s']:.1f} s | {r['in_process_s']:.1f} s | "
                   f"{r['cluster_over_in_process']:.2f} |")
    return "\n".join(out)


def scale_workers() -> str:
    d = _load("scale-workers-20m.json")
    runs = sorted(d["results"], key=lambda r: r["workers"])
    cols = [f"{r['workers']} worker{'s' if r['workers'] > 1 else ''}" for r in runs]
    p = [r["projection"] for r in runs]

    def row(name: str, f: Callable[[dict, dict], str]) -> str:
        return f"| {name} | " + " | ".join(f(r, q) for r, q in zip(runs, p, strict=True)) + " |"

    out = [f"| {_n(runs[0]['points'])} points, {d['cpu']}, {d['cores']} cores | " + " | ".join(cols) + " |",
           "| --- |" + " --- |" * len(runs),
           row("measured wall", lambda r, q: f"{r['wall_s']:.1f} s"),
           row("predicted from its own units, 1 / 2 / 16 workers",
               lambda r, q: " / ".join(f"{q['predicted_s'][k]:.1f}" for k in ("1", "2", "16")) + " s"),
           row("unit seconds, all units", lambda r, q: f"{sum(w['unit_s'] for w in q['waves']):.1f} s"),
           row("driver alone / starts and new workers",
               lambda r, q: f"{sum(q['driver_s'].values()):.1f} / {q['other_s']:.1f} s"),
           row(f"{p[0]['target_points'] / 1e9:.2f} B points on 64 workers (units repeated)",
               lambda r, q: f"{q['target_64_workers_s'] / 60:.1f} min"),
           row("peak process", lambda r, q: "{:.0f} MB ({})".format(
               *max((s["peak_process"] / 1e6, s["stage"]) for s in r["stages"])))]
    one = {r["workers"]: r for r in runs}
    lom = p[0]["largest_over_median_points"]
    out += ["", f"1 worker over 2: **{one[1]['wall_s'] / one[2]['wall_s']:.2f}**; predicted 16 over 2 "
            f"(2-worker run): **{one[2]['projection']['speedup_16_over_2']:.2f}**; largest over median unit in "
            "points: " + ", ".join(f"{k} {v:.1f}x" for k, v in lom.items() if v and v > 1.5) + "."]
    return "\n".join(out)


def scale_100m() -> str:
    d = _load("scale-100m.json")
    r = d["results"][0]
    q = r["projection"]
    st = {x["stage"]: x["seconds"] for x in r["stages"]}
    rate = r["points"] / r["wall_s"]
    worst = q["unit_balance"]
    return "\n".join([
        "| points | workers | wall | points/s | over reference read | ingest / coarse / tree / labels, s | peak process |",
        "| ---: | ---: | ---: | ---: | ---: | --- | ---: |",
        f"| {_n(r['points'])} | {r['workers']} | {r['wall_s']:.1f} s | {_n(round(rate))} | "
        f"{rate / r['reference_read']:.3f} | " + " / ".join(f"{st[k]:.1f}" for k in ("ingest", "coarse", "tree", "labels"))
        + f" | {max(x['peak_process'] for x in r['stages']) / 2**20:.0f} MB |",
        "",
        "Predicted from its units, 1 / 2 / 4 / 16 / 64 workers: "
        + " / ".join(f"{q['predicted_s'][k]:.1f}" for k in ("1", "2", "4", "16", "64"))
        + f" s; 16 over 2 **{q['speedup_16_over_2']:.2f}**; {q['target_points'] / 1e9:.2f} B points on 64 workers "
        f"**{q['target_64_workers_s'] / 60:.1f} min**; driver alone {sum(q['driver_s'].values()):.1f} s, starts "
        f"{q['other_s']:.1f} s; largest unit over its wave's median, above 1.5x: "
        + ", ".join(f"{k} {v:.1f}x" for k, v in q["largest_over_median_points"].items() if v and v > 1.5)
        + f" (limit {worst['limit']:.0f}x).",
    ])


def fuzz() -> str:
    d = _load("fuzz.json")
    kinds: dict[str, Counter] = {}
    for o in d["outcomes"]:
        k = kinds.setdefault(o["spec"].split()[0], Counter())
        k["scans"] += 1
        k["points"] += o.get("n_points") or 0
        k[o["status"]] += 1
    statuses = sorted({s for k in kinds.values() for s in k} - {"scans", "points"})
    out = ["| kind | scans | points | " + " | ".join(statuses) + " |", "| --- | ---: | ---: |" + " ---: |" * len(statuses)]
    for name, k in sorted(kinds.items(), key=lambda kv: -kv[1]["scans"]):
        out.append(f"| {name} | {k['scans']} | {_n(k['points'])} | " + " | ".join(str(k[s]) for s in statuses) + " |")
    out += ["", f"{d['scans']} scans, seed {d['seed']}, at most {_n(d['max_points'])} points each: "
            f"**{d['bugs']} bugs** ({d['seconds']:.0f} s; `fuzz.json`)."]
    return "\n".join(out)


def _size(n: int) -> str:
    """A point count in round words: 100 M, 300 k."""
    return f"{n / 1e6:.0f} M" if n >= 1e6 else f"{n / 1e3:.0f} k"


def _cpu(d: dict) -> str:
    """A JSON result's CPU in a few words: "Intel Xeon", "AMD EPYC Zen 3"."""
    name = re.sub(r"\((R|TM)\)|\bProcessor\b|\bCPU\b.*", "", d.get("cpu") or "")
    return " ".join(name.split()) or "unknown CPU"


def synth() -> str:
    """``bench_synth.py``: per size wall, throughput and peak memory; the last size's memory ratio."""
    d = _load("synth.json")
    rows = d["rows"]
    out = ["| points | wall s | M points/s | M rays/s | peak RSS MB | LAZ MB |", "| ---: | ---: | ---: | ---: | ---: | ---: |"]
    for i, r in enumerate(rows):
        rate = f"{r['m_points_per_s']:.2f}"
        out.append(f"| {r['points']:,} | {r['seconds']:.1f} | {f'**{rate}**' if i == len(rows) - 1 else rate} | "
                   f"{r['m_rays_per_s']:.2f} | {r['peak_rss_mb']:.0f} | {r['laz_mb']:.1f} |")
    if len(rows) > 1:
        ratio = d["ratios"].get("peak_largest_over_previous", rows[-1]["peak_rss_mb"] / rows[-2]["peak_rss_mb"])
        out += ["", f"Peak memory {_size(rows[-1]['points'])} / {_size(rows[-2]['points'])} "
                f"**{ratio:.2f}**."]
    return "\n".join(out)


def ingest() -> str:
    """``bench_ingest.py``: per file the raw read beside the ingest; the LAZ memory ratio."""
    d = _load("ingest.json")
    out = ["| file | points | raw read M pts/s | ingest s | ingest M pts/s | ingest / raw | peak MB | CPU s raw / ingest |",
           "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in d["rows"]:
        ratio = f"{r['ingest_over_raw']:.2f}"
        out.append(f"| {r['file']} | {_n(r['points'])} | {r['raw_m_points_per_s']:.2f} | {r['ingest_s']:.1f} | "
                   f"{r['ingest_m_points_per_s']:.2f} | {f'**{ratio}**' if r['file'] == 'LAZ' else ratio} | "
                   f"{r['peak_mb']:.0f} | {r['raw_cpu_s']:.1f} / {r['ingest_cpu_s']:.1f} |")
    laz = [r for r in d["rows"] if r["file"] == "LAZ"]
    if "peak_laz_largest_over_smallest" in d["ratios"]:
        out += ["", f"Peak memory LAZ {_size(laz[-1]['points'])} / {_size(laz[0]['points'])} "
                f"**{d['ratios']['peak_laz_largest_over_smallest']:.2f}x**."]
    return "\n".join(out)


def coarse_repeats() -> str:
    """``bench_coarse.py --only-repeats``: our tile kernel against CGAL tuned, means of N runs."""
    d = _load("coarse-repeats.json")
    out = ["| site | ours: tile kernel, mean s / mean recall (per run) | CGAL tuned: mean s / mean recall (per run) "
           "| ratio of means |", "| --- | --- | --- | ---: |"]
    for s in (s for s in d["sites"] if "repeats" in s):
        r = s["repeats"]
        cells = [f"{r[f'{k}_s']:.2f} / **{r[f'{k}_recall']:.3f}** ({' '.join(f'{x:.2f}' for x in r[f'{k}_recalls'])})"
                 for k in ("ours", "cgal_tuned")]
        out.append(f"| {s['site']} | {cells[0]} | {cells[1]} | **{r['ratio_of_means']:.2f}** |")
    return "\n".join(out)


def _sig3(x: float) -> str:
    return f"{x:#.3g}".rstrip(".")


def hollownet() -> str:
    """``bench_hollownet.py``: one column per machine (``hollownet.json`` first), the paper's last."""
    runs = [_load("hollownet.json")] + [json.loads(f.read_text()) for f in sorted(RESULTS.glob("hollownet-*.json"))]
    head = runs[0]

    def row(name: str, cell: Callable[[int, dict], str], paper: str) -> str:
        return f"| {name} | " + " | ".join(cell(i, d) for i, d in enumerate(runs)) + f" | {paper} |"

    def infer(d: dict, p: str) -> str:
        a, b = (d[f"inference_ms_per_segment_b64_{p}_{t}threads"] for t in (1, 2))
        return f"{_sig3(a)} / {_sig3(b)} ms"

    def acc(i: int, d: dict) -> str:
        a, b = d["heldout_accuracy_float32"], d.get("heldout_accuracy_bfloat16")
        text = f"**{100 * a:.2f} %**" if i == 0 else f"{100 * a:.2f} %"
        return text + ("" if b is None else " (bfloat16 too)" if b == a else f" (bfloat16: {100 * b:.2f} %)")

    out = ["| measure | " + " | ".join(f"{_cpu(d)} ({', '.join(d['isa'])})" for d in runs) + " | paper |",
           "| --- |" + " --- |" * (len(runs) + 1),
           row("voxelise 100 k points (canonical yaw; each in a batch of 64)",
               lambda i, d: f"{d['voxelize_ms_canonical_False']:.2f} ms ({d['voxelize_ms_canonical_True']:.2f}; "
                            f"{d['voxelize_batch64_ms_per_segment']:.2f})", "131 ms"),
           row("inference, batch 64, float32 (default), 1 / 2 threads", lambda i, d: infer(d, "float32"), "50 ms"),
           row("inference, batch 64, bfloat16 autocast, 1 / 2 threads",
               lambda i, d: infer(d, "bfloat16") + ("" if d["bf16_native"] else " (emulated: not on such CPUs)"),
               "50 ms"),
           row(f"`Classifier.predict` on points, {head['heldout_samples']} segments",
               lambda i, d: f"{d['predict_points_ms_per_segment_float32']:.1f} ms float32" + (
                   f", {d['predict_points_ms_per_segment_bfloat16']:.1f} ms bfloat16"
                   if "predict_points_ms_per_segment_bfloat16" in d else ""), "181 ms"),
           row(f"held-out accuracy ({head['heldout_samples']} segments, seed {head['args']['seed']})", acc, "99.03 %")]
    return "\n".join(out)


def _curve(curve: str) -> str:
    if curve.startswith("none"):
        return "(no curve)"
    shape, _, r = curve.partition(" r=")
    return f"({shape} r = {r} m)"


def tree_segments() -> str:
    """``bench_tree.py``: the sequences per segment, ms and (ratio to 50 ms)."""
    d = _load("tree.json")
    names = {"arcade": "straight arcade"}
    out = ["| segment | psi | s1 (with psi) | s2 | s3 (with psi) | propose (+ storeys) |",
           "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for name, s in d["segments"].items():
        seq = [f"{1e3 * s[k]:.1f} ({s[k] / 0.05:.2f})" for k in ("s1 (with psi)", "s2", "s3 (with psi)")]
        out.append(f"| {names.get(name, name.replace('_', ' '))} {_curve(s['curve'])} | {1e3 * s['psi']:.1f} | "
                   + " | ".join(seq) + f" | {1e3 * s['propose (S1+S2+S3+storeys, one psi)']:.1f} |")
    return "\n".join(out)


def tree_whole() -> str:
    """``bench_tree.py``: the whole tree of the minaret per classifier; the default in bold."""
    d = _load("tree.json")
    out = [f"| whole tree, minaret, {_n(int(d['segments']['minaret']['n_points']))} points, max_depth 3 | "
           "total s (ratio to 1 s) | classifier s | calls | segments classified | nodes | root split |",
           "| --- | ---: | ---: | ---: | ---: | ---: | --- |"]
    for label, t in d["trees"].items():
        if not isinstance(t, dict):
            continue
        total, bold = f"{t['total']:.2f} ({t['total'] / 1.0:.2f})", "(default)" in label
        root = f"{t['root children']} x S{t['root sequence']}" if t["root children"] else "none"
        out.append(f"| {f'**{label}**' if bold else label} | {f'**{total}**' if bold else total} | "
                   f"{t['classifier']:.2f} | {t['calls']} | {t['segments classified']} | {t['nodes']} | {root} |")
    return "\n".join(out)


def workflow() -> str:
    """``bench_workflow.py``: per line of ``hollowtree run`` its time and the peaks so far (target 4 GiB)."""
    d = _load("workflow.json")
    out = ["| after stage | t (s) | peak single process (MB) | peak sum of processes (MB) |", "| --- | --- | --- | --- |"]
    for r in d["rows"]:
        name = f"outputs ({d['outputs']})" if r["line"] == "outputs" and d.get("outputs") else r["line"]
        out.append(f"| {name} | {r['t_s']:.1f} | {r['peak_process_mb']:.0f} | {r['peak_sum_mb']:.0f} |")
    out += ["", f"Peak of all processes **{d['peak_sum_gib']:.2f} GiB** ({d['peak_sum_gib'] / 4:.2f} of the target); "
            f"wall {d['wall_s']:.0f} s."]
    return "\n".join(out)


def store() -> str:
    """``bench_store.py``: requests and seconds per store and way of writing."""
    d = _load("store.json")
    out = ["| store | way | requests | per array | s |", "| --- | --- | --- | --- | --- |"]
    for r in d["rows"]:
        way = f"Zarr `{r['way'][5:]}`" if r["way"].startswith("zarr ") else f"`{r['way']}`"
        req = "-" if r["requests"] is None else _n(r["requests"])
        per = "-" if r["per_array"] is None else f"{r['per_array']:.1f}"
        out.append(f"| {r['store']} | {way} | {req} | {per} | {r['s']:.2f} |")
    q = d["ratios"]
    out += ["", f"write_unit / Zarr: **{q['s3_requests']:.2f} of the requests**, {q['s3_time']:.2f} of the time on "
            f"S3, {q['local_time']:.2f} locally."]
    return "\n".join(out)


# --- docs/results.md ---------------------------------------------------------------------

def five_sites() -> str:
    """The paper's five sites at 10 M points (``hollowtree evaluate --seeds 3 --json``):
    Table 1 beside the paper's (seed 0), then mean (min to max) over the seeds."""
    d = json.loads((RESULTS / LATEST["five-sites"]).read_text())
    code = ", ".join(f"`{d[k]}`" for k in ("tree_algorithm", "coarse_algorithm", "grid_algorithm"))
    return "\n".join([f"{code}, seed 0, source `{LATEST['five-sites']}`:", "", table1(d), "",
                      f"Mean (min to max) over seeds 0 to {d['spread']['n_seeds'] - 1} (`coarse.seed`, `tree.seed`):",
                      "", spread_table(d["spread"])])


# --- docs/decisions/method.md ------------------------------------------------------------

def _three_rows(name: str) -> tuple[float, float, float] | None:
    """F1 of one run's three validation rows (0.5-2 M, 4 M, and 10 M on its 14 sites, the
    sites 100 000-100 006 with 100 007-100 013 of ``val-10m-b``), or None where one is
    missing."""
    files = [RESULTS / f"generalize-{row}-{name}.json" for row in ("val", "val-4m", "val-density-10m", "val-10m-b")]
    if not all(f.is_file() for f in files):
        return None
    a, b, c, d = (json.loads(f.read_text()) for f in files)
    return _f1(a), _f1(b), _f1(c, d)


def _pooled_classes(name: str) -> dict[str, float] | None:
    """Each class's F1 over the sites of the three rows and the dome batch together (the
    selection rule's, ``benchmarks/choose.py``), or None where a row is missing."""
    files = [RESULTS / f"generalize-{row}-{name}.json"
             for row in ("val", "val-4m", "val-density-10m", "val-10m-b", "val-domes")]
    if not all(f.is_file() for f in files):
        return None
    runs = [json.loads(f.read_text())["totals"]["tree"] for f in files]
    return {c: 2 * sum(t[c]["found"] for t in runs) / max(sum(t[c]["gt"] + t[c]["pred"] for t in runs), 1)
            for c in ELEMENTS}


def val_seeds() -> str:
    """Each variant of :data:`VAL_SEEDS`, averaged over tree seeds 0-2: each row's F1, the F1
    sum per seed with its mean (the selection rule to ``tree-v46``), and each class's F1
    pooled over the rows' and the dome batch's sites with their mean (the rule from
    ``tree-v47``), where run."""
    out = ["| variant | 0.5-2 M | 4 M | 10 M | F1 sum, seeds 0 / 1 / 2 | mean | arch / dome / minaret / pillar | class mean |",
           "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, what in VAL_SEEDS.items():
        seeds = [name if k == 0 else f"{name}-seed{k}" for k in range(3)]
        runs = [r for r in map(_three_rows, seeds) if r is not None]
        if not runs:
            continue
        sums = [sum(r) for r in runs]
        rows = [sum(r[j] for r in runs) / len(runs) for j in range(3)]
        pooled = [p for p in map(_pooled_classes, seeds) if p is not None]
        cls = {c: sum(p[c] for p in pooled) / len(pooled) for c in ELEMENTS} if len(pooled) == len(runs) else None
        out.append(f"| {what} | " + " | ".join(f"{x:.3f}" for x in rows) + " | "
                   + " / ".join(f"{x:.3f}" for x in sums) + f" | **{sum(sums) / len(sums):.3f}** | "
                   + (" / ".join(f"{cls[c]:.3f}" for c in ELEMENTS) + f" | **{sum(cls.values()) / 4:.4f}** |"
                      if cls else "- | - |"))
    return "\n".join(out)


def val_classes(names: list[str]) -> str:
    """Per element class, each variant of :data:`VAL_SEEDS` named (or every one): found,
    predicted and F1 over the sites of its three validation rows and the dome batch (the
    selection rule's, ``benchmarks/choose.py``), averaged over the tree seeds run: what a
    variant trades between classes."""
    out = ["| variant | seeds | " + " | ".join(f"{c} found / pred / F1" for c in ELEMENTS) + " |",
           "| --- | --- | " + " | ".join("---" for _ in ELEMENTS) + " |"]
    for name in names or list(VAL_SEEDS):
        per = {c: [0.0, 0.0, 0.0] for c in ELEMENTS}  # found, predicted, true; summed over rows and seeds
        seeds = 0
        for k in range(3):
            files = [RESULTS / f"generalize-{row}-{name if k == 0 else f'{name}-seed{k}'}.json"
                     for row in ("val", "val-4m", "val-density-10m", "val-10m-b", "val-domes")]
            if not all(f.is_file() for f in files):
                continue
            seeds += 1
            for f in files:
                t = json.loads(f.read_text())["totals"]["tree"]
                for c in ELEMENTS:
                    per[c] = [a + b for a, b in zip(per[c], (t[c]["found"], t[c]["pred"], t[c]["gt"]), strict=True)]
        if seeds:
            out.append(f"| {name} | {seeds} | " + " | ".join(
                f"{fd / seeds:.1f} / {pr / seeds:.1f} / {2 * fd / max(pr + gt, 1):.3f}"
                for fd, pr, gt in per.values()) + " |")
    return "\n".join(out)


# --- docs/workflows.md -------------------------------------------------------------------

def _resolve(schema: dict, node: dict) -> dict:
    while "$ref" in node:
        node = schema["$defs"][node["$ref"].split("/")[-1]]
    return node


def _type(schema: dict, node: dict) -> tuple[str, list[str]]:
    """A field's type in words and its constraints."""
    if "anyOf" in node:
        parts = [_type(schema, n) for n in node["anyOf"]]
        types = [t for t, _ in parts if t != "null"]
        cons = [c for _, cs in parts for c in cs]
        return " or ".join(types) + (" or null" if len(types) < len(parts) else ""), cons
    if "$ref" in node:
        return "section", []
    cons = []
    for key, op in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<")):
        if key in node:
            cons.append(f"{op} {node[key]:g}")
    if "const" in node:
        cons.append(f"= {json.dumps(node['const'])}")
    if "enum" in node:
        return " \\| ".join(f"`{v}`" for v in node["enum"]), cons
    t = node.get("type", "any")
    if t == "array":
        if "prefixItems" in node:
            inner = [_type(schema, n)[0] for n in node["prefixItems"]]
            return f"[{', '.join(inner)}]", cons
        inner, icons = _type(schema, node.get("items", {}))
        return f"list of {inner}", cons + [f"each {c}" for c in icons]
    if t == "object" and "additionalProperties" in node and isinstance(node["additionalProperties"], dict):
        return f"map of {_type(schema, node['additionalProperties'])[0]}", cons
    return {"integer": "int", "number": "float", "string": "str", "boolean": "bool"}.get(t, t), cons


def _default(node: dict, required: bool) -> str:
    if required:
        return "required"
    if "default" not in node:
        t = node.get("type")
        return "`[]`" if t == "array" else "`{}`" if t == "object" else "-"
    v = node["default"]
    return "`" + (v if isinstance(v, str) else json.dumps(v)) + "`"


def _clean(text: str) -> str:
    return " ".join(text.replace("``", "`").split()).replace("|", "\\|")


def workflow_keys() -> str:
    """Every key of a workflow file, from the pydantic model's JSON schema."""
    sys.path.insert(0, str(REPO))
    from hollowtree.pipeline.workflow import Workflow

    schema = Workflow.model_json_schema()
    out = ["| key | type | default | constraints | meaning |", "| --- | --- | --- | --- | --- |"]

    def walk(node: dict, prefix: str) -> None:
        node = _resolve(schema, node)
        required = set(node.get("required", ()))
        for name, field in node.get("properties", {}).items():
            key = prefix + name
            sub = next((n for n in [field, *field.get("anyOf", ())] if "$ref" in n), None)
            if sub is not None:
                section = _resolve(schema, sub)
                desc = section.get("description", "") or field.get("description", "")
                opt = "section or null" if "anyOf" in field else "section"
                out.append(f"| `{key}` | {opt} | {'required' if name in required else ''} | | {_clean(desc)} |")
                walk(sub, key + ".")
                continue
            t, cons = _type(schema, field)
            out.append(f"| `{key}` | {t} | {_default(field, name in required)} | {', '.join(cons)} | "
                       f"{_clean(field.get('description', ''))} |")

    walk(schema, "")
    return "\n".join(out)


GENERATORS: dict[str, Callable[[], str]] = {
    "generalize-figures": generalize_figures,
    "generalize-test": generalize_test,
    "density": density,
    "small": small,
    "scale-workers": scale_workers,
    "scale-100m": scale_100m,
    "fuzz": fuzz,
    "synth": synth,
    "ingest": ingest,
    "coarse-repeats": coarse_repeats,
    "hollownet": hollownet,
    "tree-segments": tree_segments,
    "tree-whole": tree_whole,
    "workflow": workflow,
    "store": store,
    "five-sites": five_sites,
    "val-seeds": val_seeds,
    "workflow-keys": workflow_keys,
}


def doc_files() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def render(text: str, cache: dict[str, str], where: str = "") -> str:
    """``text`` with every generated block rewritten."""
    out, pos = [], 0
    for m in BEGIN.finditer(text):
        if m.start() < pos:
            continue
        end = text.find(END, m.end())
        if end < 0:
            raise SystemExit(f"{where}: '{m.group(0).strip()}' has no '{END}'")
        name = m.group(1)
        if name not in GENERATORS:
            raise SystemExit(f"{where}: unknown generated block {name!r} (known: {', '.join(GENERATORS)})")
        if name not in cache:
            cache[name] = GENERATORS[name]().rstrip("\n") + "\n\n"
        out += [text[pos:m.end()], cache[name]]
        pos = end
    out.append(text[pos:])
    return "".join(out)


def stale(files: list[Path] | None = None) -> list[str]:
    """The docs whose generated blocks differ from what the generators give now."""
    cache: dict[str, str] = {}
    return [p.relative_to(REPO).as_posix() for p in files or doc_files()
            if render(t := p.read_text(), cache, p.name) != t]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 when a doc is out of date")
    ap.add_argument("--classes", nargs="*", default=None, metavar="VARIANT",
                    help="write nothing; print each class's validation figures of these VAL_SEEDS variants (or all)")
    args = ap.parse_args(argv)
    if args.classes is not None:
        unknown = [n for n in args.classes if n not in VAL_SEEDS]
        if unknown:
            ap.error(f"--classes: {unknown[0]!r} is not a variant of VAL_SEEDS ({', '.join(VAL_SEEDS)})")
        print(val_classes(args.classes))
        return 0
    if args.check:
        bad = stale()
        for name in bad:
            print(f"{name}: generated tables out of date (run python benchmarks/report.py)")
        return 1 if bad else 0
    cache: dict[str, str] = {}
    for p in doc_files():
        text = p.read_text()
        new = render(text, cache, p.name)
        if new != text:
            p.write_text(new)
            print(f"rewrote {p.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
