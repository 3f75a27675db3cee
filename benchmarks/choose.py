"""The selection rule of docs/generalize.md as one command: run a variant's validation rows
on tree seeds 0, 1 and 2 and judge it against the default's.

A *variant* is the code in the working tree plus ``--set`` overrides, under a name. For each
tree seed and each row of :data:`ROWS` the script runs ``bench_generalize.py`` (``--no-energy``,
``--set tree.seed=K``) and writes ``benchmarks/results/generalize-<row>-<name>[-seedK].json``
(seed 0 has no suffix), the files ``report.py`` reads. A row whose file exists is read, not
rerun, so an interrupted run picks up where it stopped; ``--force`` reruns. The scans and
their stores live in ``--work`` (one folder per row): the coarse stage of every variant after
the first resumes from them, only the tree reruns.

Then it prints, for the variant and ``--against`` (the default's name), each seed's F1 per
row and the three-row sum (0.5-2 M + 4 M + 10 M on 14 sites), and each class's element F1
pooled over the sites of the sum's rows and the dome batch (:data:`CLASS_ROWS`). The
verdict: *keep* when the macro mean of those four class F1s, averaged over the seeds, rises
with a paired bootstrap interval (:func:`macro_interval`: the validation sites resampled, each
with all its rows, the same sites for both sides) whose lower end is above zero, and no class's
F1 fell by more than the default's own range over the seeds (its seed-to-seed spread). The
macro mean weighs each class as the issue's per-class target does; the sum, ~60 % arches,
could not see a change in domes. Both must have run in one environment, the same CPU model
and numeric packages (labels move with either; the JSON's ``machine``): the script says so
when they did not. The sum's paired interval (:func:`paired_interval`) is printed beside it.

Run: ``python benchmarks/choose.py NAME [--set KEY=VALUE ...] [--seeds 0 1 2] [--rows ...]
[--against tree-v47]``; ``--judge`` only reads the JSONs. A row's full run on 2 cores: about
4 (0.5-2 M), 7 (4 M) and 2 x 8 (10 M) minutes, the dome batch 5; the first run of a row also
scans its sites and runs their coarse stage. Validation seeds only: the test split is never
used to choose (docs/generalize.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
for p in (REPO, REPO / "benchmarks"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

RESULTS = REPO / "benchmarks" / "results"

#: Each validation row: its name in the JSON files and ``bench_generalize.py``'s arguments.
ROWS: dict[str, list[str]] = {
    "val": ["--sites", "14", "--points", "5e5", "2e6"],
    "val-4m": ["--sites", "14", "--points", "4e6", "4e6"],
    "val-density-10m": ["--sites", "7", "--points", "1e7", "1e7"],
    "val-10m-b": ["--skip", "7", "--sites", "7", "--points", "1e7", "1e7"],
    # the dome batch: the next 6 validation seeds of each family with domes
    "val-domes": ["--family", "courtyard_mosque", "linear_facade", "pavilion_garden", "monument", "--skip", "4",
                  "--sites", "6", "--points", "5e5", "2e6"],
}
#: The rows of the sum; the 10 M row is its two halves' sites together.
SUM_ROWS = ("val", "val-4m", "val-density-10m", "val-10m-b")
#: The two-sided level of the paired intervals; a variant is kept when the lower end of the
#: macro mean's gain is above zero (above :data:`ZERO`: a resample without the sites that
#: moved gains nothing but rounding).
LEVEL = 0.9
ZERO = 1e-9
ELEMENTS = ("arch", "dome", "minaret", "pillar")
#: The rows whose sites each class's F1 is pooled over for the veto: the sum's and the dome
#: batch (the sum's rows alone hold about 16 domes each).
CLASS_ROWS = (*SUM_ROWS, "val-domes")


def result_path(row: str, name: str, seed: int) -> Path:
    """The JSON of one row of a variant at one tree seed (seed 0: no suffix)."""
    return RESULTS / f"generalize-{row}-{name}{'' if seed == 0 else f'-seed{seed}'}.json"


def f1(*runs: dict) -> float:
    """Element F1 (all four classes) of one run, or of several runs' sites together."""
    tot = [sum(d["totals"]["tree"][c][k] for d in runs for c in ELEMENTS) for k in ("found", "gt", "matched", "pred")]
    found, gt, matched, pred = tot
    r, p = found / max(gt, 1), matched / max(pred, 1)
    return 2 * r * p / (r + p) if r + p else 0.0


def class_f1(*runs: dict) -> dict[str, float]:
    """Each class's F1 in one run, or over several runs' sites together."""
    out = {}
    for c in ELEMENTS:
        found, gt, pred = (sum(d["totals"]["tree"][c][k] for d in runs) for k in ("found", "gt", "pred"))
        out[c] = 2 * found / max(gt + pred, 1)
    return out


def pooled_class_f1(name: str, seed: int) -> dict[str, float] | None:
    """:func:`class_f1` over the sites of every row of :data:`CLASS_ROWS` at one tree seed;
    None where a row is missing."""
    files = [result_path(r, name, seed) for r in CLASS_ROWS]
    if not all(f.is_file() for f in files):
        return None
    return class_f1(*(json.loads(f.read_text()) for f in files))


def three_rows(name: str, seed: int) -> tuple[float, float, float] | None:
    """F1 of the 0.5-2 M, 4 M and 10 M (14 sites) rows, or None where one is missing."""
    files = [result_path(r, name, seed) for r in SUM_ROWS]
    if not all(f.is_file() for f in files):
        return None
    a, b, c, d = (json.loads(f.read_text()) for f in files)
    return f1(a), f1(b), f1(c, d)


def _per_site(name: str, seeds: list[int], rows: tuple[str, ...]) -> list[tuple[int, str, list[dict]]] | None:
    """(tree seed, row, its sites) of each of ``rows`` at each seed; None where a JSON is
    missing or records no per-site totals."""
    out = []
    for s in seeds:
        for r in rows:
            f = result_path(r, name, s)
            if not f.is_file():
                return None
            sites = json.loads(f.read_text()).get("sites", [])
            if not sites or any("totals" not in x for x in sites):
                return None
            out.append((s, r, sites))
    return out


def _site_counts(name: str, seeds: list[int]) -> dict[tuple[int, str], dict[int, list[int]]] | None:
    """Per seed and sum row, each site's (found, gt, matched, pred) over the four classes,
    keyed by the site's seed; None where a JSON is missing or records no per-site totals."""
    runs = _per_site(name, seeds, SUM_ROWS)
    if runs is None:
        return None
    out: dict[tuple[int, str], dict[int, list[int]]] = {}
    for s, r, sites in runs:
        key = (s, "val-10m" if r in ("val-density-10m", "val-10m-b") else r)
        for x in sites:
            t = x["totals"]
            out.setdefault(key, {})[x["seed"]] = [sum(t[c][k] for c in ELEMENTS)
                                                  for k in ("found", "gt", "matched", "pred")]
    return out


def paired_interval(name: str, against: str, seeds: list[int], *, draws: int = 2000,
                    level: float = 0.9) -> tuple[float, float] | None:
    """The gain of ``name``'s mean three-row sum over ``against``'s, as a ``level`` interval
    from resampling the sites of each row (the same sites for both, at every tree seed: a
    paired bootstrap). None where either side's JSONs lack per-site totals."""
    import numpy as np

    a, b = _site_counts(against, seeds), _site_counts(name, seeds)
    if a is None or b is None or a.keys() != b.keys():
        return None
    rng = np.random.default_rng(0)
    rows = sorted({r for _, r in a})
    gains = np.zeros(draws)
    for r in rows:
        ids = sorted(set.intersection(*(set(a[(s, r)]) & set(b[(s, r)]) for s in seeds)))
        if not ids:  # no site in common: nothing to pair
            return None
        pick = rng.integers(0, len(ids), (draws, len(ids)))
        for side, sign in ((b, 1.0), (a, -1.0)):
            for s in seeds:
                c = np.asarray([side[(s, r)][i] for i in ids], dtype=np.float64)[pick].sum(axis=1)
                rec, prec = c[:, 0] / np.maximum(c[:, 1], 1), c[:, 2] / np.maximum(c[:, 3], 1)
                f = np.where(rec + prec > 0, 2 * rec * prec / np.maximum(rec + prec, 1e-12), 0.0)
                gains += sign * f / len(seeds)
    lo, hi = np.quantile(gains, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def _class_site_counts(name: str, seeds: list[int]) -> dict[int, dict[int, object]] | None:
    """Per tree seed, each validation site's (found, gt, pred) per class (rows of
    :data:`ELEMENTS`), summed over the rows of :data:`CLASS_ROWS` that hold the site (one
    site at 0.5-2, 4 and 10 M is one draw of the bootstrap); None where a JSON is missing or
    records no per-site totals."""
    import numpy as np

    runs = _per_site(name, seeds, CLASS_ROWS)
    if runs is None:
        return None
    out: dict[int, dict[int, np.ndarray]] = {}
    for s, _, sites in runs:
        for x in sites:
            c = np.asarray([[x["totals"][e][k] for k in ("found", "gt", "pred")] for e in ELEMENTS], float)
            site = out.setdefault(s, {})
            site[x["seed"]] = site.get(x["seed"], 0) + c
    return out


def macro_f1(counts):
    """The mean over :data:`ELEMENTS` of each class's F1 from (..., class, (found, gt, pred))
    counts; a class with neither elements nor predictions counts as 1 (nothing to find, no
    false call)."""
    import numpy as np

    found, gt, pred = counts[..., 0], counts[..., 1], counts[..., 2]
    return np.where(gt + pred > 0, 2 * found / np.maximum(gt + pred, 1), 1.0).mean(axis=-1)


def macro_interval(name: str, against: str, seeds: list[int], *, draws: int = 2000,
                   level: float = LEVEL) -> tuple[float, float, float] | None:
    """The gain of ``name``'s macro mean of the pooled class F1s over ``against``'s, averaged
    over ``seeds``, and a ``level`` interval of it from resampling the validation sites (each
    site with all its rows, the same draw for both sides at every tree seed: a paired
    bootstrap). None where either side lacks per-site totals or they share no site."""
    import numpy as np

    a, b = _class_site_counts(against, seeds), _class_site_counts(name, seeds)
    if a is None or b is None:
        return None
    ids = sorted(set.intersection(*(set(side[s]) for side in (a, b) for s in seeds)))
    if not ids:
        return None
    pick = np.random.default_rng(0).integers(0, len(ids), (draws, len(ids)))
    gain, gains = 0.0, np.zeros(draws)
    for side, sign in ((b, 1.0), (a, -1.0)):
        for s in seeds:
            c = np.stack([side[s][i] for i in ids])  # (sites, class, 3)
            gain += sign * float(macro_f1(c.sum(axis=0))) / len(seeds)
            gains += sign * macro_f1(c[pick].sum(axis=1)) / len(seeds)
    lo, hi = np.quantile(gains, [(1 - level) / 2, (1 + level) / 2])
    return gain, float(lo), float(hi)


def environment(run: dict) -> str:
    """A run's CPU model and numeric packages (``machine`` of its JSON), as one line."""
    m = run.get("machine", {})
    pk = m.get("packages")
    return m.get("cpu", "unknown CPU") + (", " + ", ".join(f"{k} {v}" for k, v in sorted(pk.items()))
                                          if pk else ", packages not recorded")


def environments(name: str, seeds: list[int]) -> set[str]:
    """The environments (:func:`environment`) a variant's JSONs were made in."""
    out = set()
    for s in seeds:
        for r in ROWS:
            f = result_path(r, name, s)
            if f.is_file():
                out.add(environment(json.loads(f.read_text())))
    return out


def judge(name: str, against: str, seeds: list[int]) -> tuple[str, list[str]]:
    """The verdict on ``name`` against ``against`` and the lines of its table."""
    lines = [f"{'variant':<28}" + "".join(f"{'seed ' + str(s):>24}" for s in seeds) + f"{'mean':>8}{'range':>8}",
             f"{'':<28}" + "".join(f"{'0.5-2M / 4M / 10M = sum':>24}" for _ in seeds)]
    means = {}
    for n in (against, name):
        rows = [three_rows(n, s) for s in seeds]
        cells = [f"{r[0]:.3f}/{r[1]:.3f}/{r[2]:.3f}={sum(r):.3f}" if r else "(not run)" for r in rows]
        done = [sum(r) for r in rows if r]
        means[n] = sum(done) / len(done) if len(done) == len(seeds) else None
        lines.append(f"{n:<28}" + "".join(f"{c:>24}" for c in cells)
                     + (f"{means[n]:>8.3f}{max(done) - min(done):>8.3f}" if means[n] is not None else f"{'-':>8}"))
    pooled = {n: {s: pooled_class_f1(n, s) for s in seeds} for n in (against, name)}
    have = [s for s in seeds if all(pooled[n][s] is not None for n in (against, name))]
    fallen = []
    if have:
        a, b = ({c: [pooled[n][s][c] for s in have] for c in ELEMENTS} for n in (against, name))
        tol = {c: max(a[c]) - min(a[c]) for c in ELEMENTS}  # the default's own spread over the seeds
        lines.append(f"F1 per class over the four rows' and the dome batch's sites, mean over seeds "
                     f"{', '.join(map(str, have))} (the default's range): "
                     + ", ".join(f"{c} {sum(a[c]) / len(have):.3f} -> {sum(b[c]) / len(have):.3f} ({tol[c]:.3f})"
                                 for c in ELEMENTS))
        fallen = [c for c in ELEMENTS if sum(a[c]) - sum(b[c]) > len(have) * tol[c] + 1e-12]
    envs = environments(name, seeds) | environments(against, seeds)
    if len(envs) > 1:
        lines.append("the runs were made in different environments (labels move with the CPU model and the "
                     "numeric packages): rerun the default here under another name and judge against that:")
        lines += [f"  {e}" for e in sorted(envs)]
    if means[name] is None or means[against] is None:
        return "not judged: a row is missing", lines
    ci = paired_interval(name, against, seeds)
    lines.append("the sum's gain: paired over the sites, 90 % of resamples put it in "
                 + (f"[{ci[0]:+.3f}, {ci[1]:+.3f}]" if ci else "(not known: a side's JSONs hold no per-site totals)"))
    if len(have) < len(seeds):
        missing = ", ".join(str(s) for s in seeds if s not in have)
        return f"not judged: the dome batch is missing at seed {missing}", lines
    macro = macro_interval(name, against, seeds)
    if macro is None:
        return "not judged: a side's JSONs hold no per-site totals (rerun the default with this choose.py)", lines
    gain, lo, hi = macro
    lines.append(f"the macro mean of the class F1s: {gain:+.4f}, {LEVEL:.0%} of paired resamples of the sites "
                 f"in [{lo:+.4f}, {hi:+.4f}]")
    if lo > ZERO and not fallen:
        return f"keep: macro mean {gain:+.4f}, interval [{lo:+.4f}, {hi:+.4f}] above zero", lines
    why = ([] if lo > ZERO else [f"macro mean {gain:+.4f}, its interval [{lo:+.4f}, {hi:+.4f}] reaches zero"]) + [
        f"the {c} F1 fell by more than the default's range" for c in fallen]
    return "reject: " + "; ".join(why), lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name", help="the variant's name in the JSON files (e.g. tree-v49)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="a workflow override of the variant, repeatable")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], metavar="K", help="tree seeds (default 0 1 2)")
    ap.add_argument("--rows", nargs="+", choices=list(ROWS), default=list(ROWS), metavar="ROW",
                    help=f"rows to run (default all: {', '.join(ROWS)})")
    ap.add_argument("--against", default="tree-v47", metavar="NAME",
                    help="the default's run in this environment (default tree-v47, made with constraints.txt)")
    ap.add_argument("--work", type=Path, default=REPO / "out" / "choose", help="scans and stores, one folder per row")
    ap.add_argument("--force", action="store_true", help="rerun rows whose JSON exists")
    ap.add_argument("--judge", action="store_true", help="run nothing; judge the JSONs there are")
    args = ap.parse_args(argv)
    if any(s < 0 for s in args.seeds):
        ap.error("--seeds must be 0 or more")
    bad = [o for o in args.overrides if "=" not in o or o.split("=", 1)[0].strip() == "tree.seed"]
    if bad:
        ap.error(f"--set {bad[0]!r}: give KEY=VALUE (tree.seed is the script's)")
    if not args.judge:
        import bench_generalize

        for seed in args.seeds:
            for row in args.rows:
                out = result_path(row, args.name, seed)
                if out.is_file() and not args.force:
                    continue
                print(f"== {args.name}, tree seed {seed}, row {row}", flush=True)
                argv_row = ["--split", "val", *ROWS[row], "--no-energy", "--work", str(args.work / row),
                            "--json", str(out), "--set", f"tree.seed={seed}"]
                for o in args.overrides:
                    argv_row += ["--set", o]
                bench_generalize.main(argv_row)
    verdict, lines = judge(args.name, args.against, args.seeds)
    print("\n".join(lines))
    print(verdict)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
