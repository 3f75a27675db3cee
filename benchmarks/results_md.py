"""Markdown tables for docs/results.md from the JSON of ``hollowtree evaluate``.

Run: ``python benchmarks/results_md.py out/evaluate/evaluate.json``. Prints the Table 1
comparison with the paper (the first seed), one table per site and method, the mean IoU
summary, then, for a run with ``--seeds N``, the spread over the seeds. The Table 1 and
spread tables of docs/results.md are generated from the checked-in JSON by
``benchmarks/report.py`` with the same functions.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

#: The paper's Table 1 (../shared/METHOD.md): GT / AG / Acc % for arches, domes, minarets.
PAPER = {
    "wazir_khan": ("46/19/41.3", "12/12/100", "6/6/100"),
    "khudabad": ("12/7/58.3", "21/19/90.4", "0/0/NA"),
    "derawar": ("0/0/NA", "0/0/NA", "38/38/100"),
    "roman": ("79/77/97.4", "0/0/NA", "0/0/NA"),
    "temple": ("0/0/NA", "7/7/100", "4/0/0"),
}
ELEMENTS = ("arch", "dome", "minaret", "pillar")


def _f(v: float | None) -> str:
    return "NA" if v is None else f"{v:.1f}"


def _gaa(c: dict) -> str:
    return f"{c['n_gt']}/{c['n_found']}/{_f(c['accuracy_pct'])}"


def table1(d: dict) -> str:
    """The paper's Table 1 beside the tree's GT / AG / Acc % (the run's first seed)."""
    out = ["| site | paper arches | ours arches | paper domes | ours domes | paper minarets | ours minarets |",
           "| --- | --- | --- | --- | --- | --- | --- |"]
    for s in d["sites"]:
        c = s["methods"]["tree"]["classes"]
        p = PAPER.get(s["name"], ("-", "-", "-"))
        out.append(f"| {s['name']} | {p[0]} | {_gaa(c['arch'])} | {p[1]} | {_gaa(c['dome'])} | {p[2]} | "
                   f"{_gaa(c['minaret'])} |")
    return "\n".join(out)


def _r(s: dict, signed: bool = False) -> str:
    f = "+.1f" if signed else ".1f"
    return f"{s['mean']:{f}} ({s['min']:{f}} to {s['max']:{f}})"


def spread_table(sp: dict) -> str:
    """Mean (min to max) over the seeds, per site and over all sites."""
    out = ["| site | tree mean IoU % | tree - ransac+dbscan | arches found | domes found | minarets found |",
           "| --- | --- | --- | --- | --- | --- |"]
    rows = [*sp["sites"].items(), (f"all {len(sp['sites'])} sites", sp["all"])]
    for name, s in rows:
        found = [f"{_r(s['found'][c])} of {s['found'][c]['n_gt']}" if c in s["found"] else "-"
                 for c in ("arch", "dome", "minaret")]
        out.append(f"| {name} | {_r(s['tree_mean_iou_pct'])} | {_r(s['tree_minus_ransac+dbscan'], True)} | "
                   + " | ".join(found) + " |")
    return "\n".join(out)


def details(d: dict) -> str:
    """One table per site and method, then the mean IoU per site and method."""
    out = []
    for s in d["sites"]:
        out += [f"\n### {s['name']} ({s['n_points']:,} points, {s['n_segments']} coarse segments, "
                f"{s['n_primitives']} stitched RANSAC primitives)\n",
                "| method | class | GT | AG | Acc % | pred | prec % | point IoU % |",
                "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for m, ev in s["methods"].items():
            first = True
            for name in ("ground", "wall", "roof", *ELEMENTS, "other"):
                c = ev["classes"][name]
                if not (c["n_gt"] or c["n_pred"]):
                    continue
                out.append(f"| {m if first else ''} | {name} | {c['n_gt']} | {c['n_found']} | "
                           f"{_f(c['accuracy_pct'])} | {c['n_pred']} | {_f(c['precision_pct'])} | {_f(c['iou_pct'])} |")
                first = False
            n_cls = sum(1 for c in ev["classes"].values() if c["n_gt"] and c["class_id"] != 0)
            out.append(f"| | **mean IoU ({n_cls} classes)** | | | | | | **{_f(ev['mean_iou_pct'])}** |")
    out += ["\n| site | ransac | ransac+dbscan | tree | tree - ransac+dbscan |", "| --- | ---: | ---: | ---: | ---: |"]
    for s in d["sites"]:
        m = {k: v["mean_iou_pct"] for k, v in s["methods"].items()}
        out.append(f"| {s['name']} | {_f(m['ransac'])} | {_f(m['ransac+dbscan'])} | {_f(m['tree'])} | "
                   f"{m['tree'] - m['ransac+dbscan']:+.1f} |")
    return "\n".join(out)


def main(path: str) -> None:
    d = json.loads(Path(path).read_text())
    print(table1(d))
    print(details(d))
    if "spread" in d:
        sp = d["spread"]
        print(f"\nOver {sp['n_seeds']} seeds (coarse.seed and tree.seed +0 .. +{sp['n_seeds'] - 1}), "
              "mean (min to max):\n")
        print(spread_table(sp))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "out/evaluate/evaluate.json")
