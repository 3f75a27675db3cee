"""Fit the element check (tree/verify.py) and sweep its threshold.

``fit``: every finished store of ``bench_generalize --split train`` work folders (run
with the element check off), or of a user's labelled scans run through a workflow (their
source files holding ``gt_class`` and ``gt_instance``), gives one row per element
instance after the merge: its features (:func:`tree.verify.instance_features`) and the
class of the element its final instance matches (IoU >= 0.5, any element class; none
if it matches none). One gradient-boosted classifier per element class (the split
model's settings) is fitted on them, its AUC measured by 5-fold cross-validation grouped
by site, and the four are written as one :class:`tree.verify.ElementCheck` file. A
procedural store of a seed that is not a training seed is refused. ``--choose-thresholds``
also chooses each class's threshold on the training sites: the cross-validation's
out-of-fold probabilities decide every instance as the check would, and the thresholds
that give the best F1 of all elements together are written with the models.

``sweep``: on the stores of a validation work folder (element check off), what each
threshold would do (an instance takes its most probable class when that reaches the
threshold, else ``other``; ``--reject-only`` never changes a class; ``--vary CLASS``
sweeps that class's threshold alone, the others keeping the model's): found elements and
precision per threshold, so the thresholds are chosen on validation seeds. It ignores
that a rejected arch no longer joins an arcade row, so the chosen threshold is checked
with a real run.

Run: ``python benchmarks/fit_verify.py fit out/gen-train out/gen-train4m --out check.json
--threshold 0.1 --class-threshold pillar=0.4 --choose-thresholds`` and ``python
benchmarks/fit_verify.py sweep out/gen-val4m --model check.json``. The shipped
``tree/data/verify-v3.json``: verify-v2's models (training seeds 0-59 at 0.5-2 M and 1-4 M),
the dome and minaret thresholds chosen on the 0.5-2 M half, arch and pillar kept.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402

from hollowtree.classes import ELEMENT_CLASSES, ClassId, class_id  # noqa: E402
from hollowtree.pipeline.tree_stage import MERGE_MAP, _ground_levels, _merge_map, element_instances  # noqa: E402
from hollowtree.scenes.procedural import SPLITS  # noqa: E402
from hollowtree.tiling.readers import PointBlock, read_blocks  # noqa: E402
from hollowtree.tiling.store import RunStore  # noqa: E402
from hollowtree.tree.verify import VERIFY_FEATURES, ElementCheck, VerifyModel, load_verify_model  # noqa: E402

_ELEMENTS = np.asarray([int(c) for c in ELEMENT_CLASSES])


def _seed(store: Path) -> int | None:
    """The procedural seed of a ``bench_generalize`` store (``gen-v2-<seed>-<points>.zarr``,
    ``gen-<seed>-<points>.zarr`` before ``gen-v2``), else None."""
    m = re.fullmatch(r"gen(?:-v\d+)?-(\d+)-\d+", store.name.removesuffix(".zarr"))
    return int(m.group(1)) if m else None


def _matches(gc: np.ndarray, gi: np.ndarray, pc: np.ndarray, pi: np.ndarray) -> dict[int, int]:
    """Every predicted element instance (key instance * 256 + class) and the class of the
    ground-truth element (any element class) it matches at IoU >= 0.5, or 0."""
    gkey = np.where((gi > 0) & np.isin(gc, _ELEMENTS), gi.astype(np.int64) * 256 + gc, -1)
    pkey = np.where((pi > 0) & np.isin(pc, _ELEMENTS), pi.astype(np.int64) * 256 + pc, -1)
    both = (gkey >= 0) & (pkey >= 0)
    g_sz = dict(zip(*np.unique(gkey[gkey >= 0], return_counts=True), strict=True))
    p_sz = dict(zip(*np.unique(pkey[pkey >= 0], return_counts=True), strict=True))
    out = {int(k): 0 for k in p_sz}
    if both.any():
        pairs, inter = np.unique(np.c_[pkey[both], gkey[both]], axis=0, return_counts=True)
        for (p, g), n in zip(pairs.tolist(), inter.tolist(), strict=True):
            if n / (p_sz[p] + g_sz[g] - n) >= 0.5:
                out[int(p)] = int(g % 256)
    return out


def _found(m: dict[int, int]) -> tuple[int, int, dict[int, list[int]]]:
    per = {int(c): [0, 0] for c in _ELEMENTS}
    for k, g in m.items():
        per[k % 256][1] += 1
        if g == k % 256:
            per[g][0] += 1
    return sum(a for a, _ in per.values()), len(m), per


def store_rows(path: Path) -> dict[str, np.ndarray]:
    """Features, class, final key and rightness of every element instance of one store."""
    store = RunStore.open(str(path))
    tree = store.attrs["stages"]["tree"]
    offsets = list(tree["instance_offsets"])
    fmap = store.read_slice(MERGE_MAP).astype(np.int64)
    tables = []
    for b, off in enumerate(offsets):
        t = store.read_table(f"tree/tables/{b}.parquet")
        inst = np.asarray(t.column("instance").to_numpy(), dtype=np.int64)
        tables.append(t.set_column(t.schema.get_field_index("instance"), "instance",
                                   pa.array(np.where(inst > 0, inst + off, 0))))
    nodes = pa.concat_tables(tables)
    imap, cmap = _merge_map(nodes, len(fmap) - 1)
    ids, cls, feats = element_instances(nodes, imap, cmap, _ground_levels(store))
    src = store.attrs["sources"][0]["path"]
    b = PointBlock.concat(read_blocks(src))
    n = len(b)
    pc = store.read_slice("labels/class", 0, n).astype(np.int64)
    pi = store.read_slice("labels/instance", 0, n).astype(np.int64)
    gc, gi = np.asarray(b.extra["gt_class"], np.int64), np.asarray(b.extra["gt_instance"], np.int64)
    match = _matches(gc, gi, pc, pi)
    keys = fmap[ids] * 256 + cls
    # only points of a true or a predicted element count in the matching
    true = (gi > 0) & np.isin(gc, _ELEMENTS)
    keep = true | ((pi > 0) & np.isin(pc, _ELEMENTS))
    gt = np.unique(gi[true] * 256 + gc[true])
    return {"features": feats, "cls": cls, "key": keys, "target": np.asarray([match.get(int(k), 0) for k in keys]),
            "gc": gc[keep], "gi": gi[keep], "pc": pc[keep], "pi": pi[keep],
            "gt": {int(c): int((gt % 256 == c).sum()) for c in _ELEMENTS}}


def _stores(paths: list[Path]) -> list[Path]:
    """The finished stores (labels complete) of ``bench_generalize`` work folders, or the stores named."""
    out = []
    for p in [s for w in paths for s in (sorted((w / "stores").glob("*.zarr")) if (w / "stores").is_dir() else [w])]:
        labels = RunStore.open(str(p)).attrs.get("stages", {}).get("labels", {})
        if labels and labels.get("done") == labels.get("units"):
            out.append(p)
    return out


def fit(work: list[Path], out: Path, threshold: float, class_thresholds: dict[int, float] | None = None,
        choose: list[float] | None = None, keep: frozenset[int] = frozenset()) -> int:
    """Fit the check on training stores; with ``choose`` (a grid), each class's threshold
    but those of ``keep`` is chosen by :func:`choose_thresholds` on the out-of-fold
    probabilities of the cross-validation, starting from ``threshold`` and ``class_thresholds``."""
    from sklearn.ensemble import GradientBoostingClassifier
    from sklearn.metrics import roc_auc_score
    from sklearn.model_selection import GroupKFold

    lo, hi = SPLITS["train"]
    xs, ys, groups, rows = [], [], [], []
    for k, s in enumerate(_stores(work)):
        seed = _seed(s)
        if seed is not None and not lo <= seed < hi:
            raise SystemExit(f"{s}: not a training seed ({lo}-{hi - 1}); the element check is fitted on training seeds")
        r = store_rows(s)
        if choose:
            rows.append(r)
        xs.append(r["features"])
        ys.append(r["target"])
        groups.append(np.full(len(r["target"]), seed if seed is not None else -1 - k))
        print(f"{s.name}: {len(r['target'])} instances, {int((r['target'] == r['cls']).sum())} right", flush=True)
    x, y, g = np.vstack(xs), np.concatenate(ys), np.concatenate(groups)

    def model() -> GradientBoostingClassifier:
        return GradientBoostingClassifier(n_estimators=150, max_depth=3, learning_rate=0.05, subsample=0.8,
                                          random_state=0)

    models, info = {}, {"sites": sorted({int(v) for v in g if v >= 0}), "files": int(len({int(v) for v in g if v < 0})),
                        "instances": int(len(y)), "auc": {}}
    oof = np.zeros((len(y), len(_ELEMENTS)))
    for j, c in enumerate(_ELEMENTS.tolist()):
        yc = (y == c).astype(int)
        for tr, te in GroupKFold(n_splits=5).split(x, yc, g):
            oof[te, j] = model().fit(x[tr], yc[tr]).predict_proba(x[te])[:, 1]
        info["auc"][ClassId(c).label] = round(float(roc_auc_score(yc, oof[:, j])), 4)
        m = model().fit(x, yc)
        models[c] = VerifyModel.from_sklearn(m, info={"positives": int(yc.sum())})
        imp = sorted(zip(m.feature_importances_.tolist(), VERIFY_FEATURES, strict=True), reverse=True)
        print(ClassId(c).label, int(yc.sum()), "AUC", info["auc"][ClassId(c).label], "|",
              ", ".join(f"{n} {v:.2f}" for v, n in imp[:6]), flush=True)
    check = ElementCheck(models=models, threshold=threshold, info=info, class_thresholds=class_thresholds or {})
    if choose:
        probs = np.split(oof, np.cumsum([len(r["target"]) for r in rows])[:-1])
        gt = sum(sum(r["gt"].values()) for r in rows)
        f0, p0, _ = _total(rows, probs, check.thresholds(), True)
        ts, f1 = choose_thresholds(rows, probs, check.thresholds(), choose, keep)
        found, pred, per = _total(rows, probs, ts, True)
        print(f"out-of-fold, {gt} elements: thresholds {check.thresholds().tolist()} found {f0} of {p0} predicted "
              f"(F1 {2 * f0 / max(gt + p0, 1):.4f}) -> {ts.tolist()} found {found} of {pred} (F1 {f1:.4f}); "
              + " ".join(f"{ClassId(c).label}:{a}/{b}" for c, (a, b) in per.items()), flush=True)
        check = ElementCheck(models=models, threshold=threshold, info=info,
                             class_thresholds={int(c): float(t) for c, t in zip(_ELEMENTS.tolist(), ts.tolist(),
                                                                                 strict=True)})
        info["thresholds"] = {"chosen_on": "out-of-fold probabilities of the training sites (grouped 5-fold)",
                              "objective": "F1 of all elements", "grid": list(choose), "f1": round(f1, 4),
                              "kept": sorted(ClassId(c).label for c in keep),
                              "start_f1": round(2 * f0 / max(gt + p0, 1), 4)}
    check.save(out)
    return 0


def sweep(work: list[Path], model_path: Path | None, thresholds: list[float], relabel: bool,
          vary: list[str] | None = None) -> int:
    """Found and predicted elements per threshold: every class's (``vary`` empty) or, for
    each class of ``vary`` in turn, that class's, the others keeping the model's thresholds."""
    check = load_verify_model(model_path)
    rows = [store_rows(s) for s in _stores(work)]
    base = [_found(_matches(r["gc"], r["gi"], r["pc"], r["pi"])) for r in rows]
    f0, p0 = sum(b[0] for b in base), sum(b[1] for b in base)
    print(f"no check: found {f0}, predicted {p0}, precision {100 * f0 / max(p0, 1):.1f}%")
    probs = [check.probabilities(r["features"]) for r in rows]
    for one in vary or [None]:
        print(f"{'threshold':>9} {'found':>6} {'pred':>6} {'precision':>9}  per class found/pred"
              + (f" ({one}'s threshold; the others {check.thresholds().tolist()})" if one else ""))
        _sweep_rows(rows, probs, check, thresholds, relabel, one)
    return 0


def _decide(r: dict[str, np.ndarray], p: np.ndarray, ts: np.ndarray, relabel: bool) -> np.ndarray:
    """The check's class for each instance of one store (0 = rejected): as
    :meth:`tree.verify.ElementCheck.decide` (``relabel``), or keep-or-reject."""
    if not len(p):
        return np.zeros(0, dtype=np.int64)
    best = np.searchsorted(_ELEMENTS, r["cls"]) if not relabel else p.argmax(axis=1)
    return np.where(p[np.arange(len(p)), best] >= ts[best], _ELEMENTS[best], 0)


def _score(r: dict[str, np.ndarray], new: np.ndarray) -> tuple[int, int, dict[int, list[int]]]:
    """Found and predicted elements (per class too) of one store once its instances take ``new``."""
    pc, pi = r["pc"].copy(), r["pi"].copy()
    pkey = pi * 256 + pc
    for k, c in zip(r["key"].tolist(), new.tolist(), strict=True):
        if c == k % 256:
            continue
        sel = pkey == k
        if c == 0:
            pi[sel] = 0
            pc[sel] = 8
        else:
            pc[sel] = c
    return _found(_matches(r["gc"], r["gi"], pc, pi))


def _total(rows: list[dict[str, np.ndarray]], probs: list[np.ndarray], ts: np.ndarray, relabel: bool,
           cache: dict | None = None) -> tuple[int, int, dict[int, list[int]]]:
    """:func:`_score` summed over stores at thresholds ``ts``; ``cache`` keeps each store's
    score per decision vector (most thresholds leave most stores' decisions alone)."""
    found = pred = 0
    per: dict[int, list[int]] = {int(c): [0, 0] for c in _ELEMENTS}
    for k, (r, p) in enumerate(zip(rows, probs, strict=True)):
        new = _decide(r, p, ts, relabel)
        key = (k, new.tobytes())
        if cache is None or key not in cache:
            res = _score(r, new)
            if cache is not None:
                cache[key] = res
        else:
            res = cache[key]
        found += res[0]
        pred += res[1]
        for c, (x, y) in res[2].items():
            per[c][0] += x
            per[c][1] += y
    return found, pred, per


def choose_thresholds(rows: list[dict[str, np.ndarray]], probs: list[np.ndarray], start: np.ndarray,
                      grid: list[float], keep: frozenset[int] = frozenset()) -> tuple[np.ndarray, float]:
    """Each class's threshold by coordinate ascent (two passes, classes in order) on the
    F1 of all elements together, 2 found / (true + predicted), of the check's decisions on
    ``probs``; a tie keeps the current threshold, and the classes of ``keep`` keep their
    ``start``. Returns the thresholds and their F1."""
    gt = sum(sum(r["gt"].values()) for r in rows)
    cache: dict = {}

    def f1(ts: np.ndarray) -> float:
        found, pred, _ = _total(rows, probs, ts, True, cache)
        return 2.0 * found / max(gt + pred, 1)

    ts = np.asarray(start, dtype=np.float64).copy()
    best = f1(ts)
    for _ in range(2):
        for j in range(len(_ELEMENTS)):
            if int(_ELEMENTS[j]) in keep:
                continue
            for t in grid:
                trial = ts.copy()
                trial[j] = t
                v = f1(trial)
                if v > best + 1e-12:
                    ts, best = trial, v
    return ts, best


def _sweep_rows(rows: list[dict[str, np.ndarray]], probs: list[np.ndarray], check: ElementCheck,
                thresholds: list[float], relabel: bool, vary: str | None) -> None:
    for t in thresholds:
        ts = np.full(len(_ELEMENTS), t)
        if vary is not None:
            ts = check.thresholds()
            ts[int(np.searchsorted(_ELEMENTS, int(class_id(vary))))] = t
        found, pred, per = _total(rows, probs, ts, relabel)
        print(f"{t:>9.2f} {found:>6} {pred:>6} {100 * found / max(pred, 1):>8.1f}%  "
              + " ".join(f"{ClassId(c).label}:{a}/{b}" for c, (a, b) in per.items()), flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit")
    f.add_argument("work", type=Path, nargs="*", help="bench_generalize work folders (training split) or stores")
    f.add_argument("--out", type=Path, required=True)
    f.add_argument("--threshold", type=float, default=0.5)
    f.add_argument("--class-threshold", nargs="+", default=[], metavar="CLASS=T",
                   help="a class's own threshold (chosen with sweep --vary), e.g. dome=0.3")
    f.add_argument("--choose-thresholds", nargs="*", type=float, default=None, metavar="T",
                   help="choose each class's threshold on the training sites' out-of-fold probabilities "
                        "(from --threshold / --class-threshold; the grid T ..., default 0.05 to 0.8)")
    f.add_argument("--keep", nargs="+", default=[], metavar="CLASS",
                   help="with --choose-thresholds: these classes keep their --threshold / --class-threshold")
    s = sub.add_parser("sweep")
    s.add_argument("work", type=Path, nargs="+", help="bench_generalize work folders (validation split) or stores")
    s.add_argument("--model", type=Path, default=None)
    s.add_argument("--thresholds", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    s.add_argument("--reject-only", action="store_true", help="never change an instance's class, only reject it")
    s.add_argument("--vary", nargs="+", default=[], metavar="CLASS",
                   help="sweep only this class's threshold (each in turn), the others keeping the model's")
    a = ap.parse_args(argv)
    if a.cmd == "fit":
        per = {}
        # ``--class-threshold`` takes every word after it: folders named after it are work folders
        folders = [item for item in a.class_threshold if "=" not in item and Path(item).is_dir()]
        a.work += [Path(item) for item in folders]
        if not a.work:
            ap.error("fit: name at least one work folder or store")
        for item in a.class_threshold:
            if item in folders:
                continue
            name, _, t = item.partition("=")
            try:
                c, v = int(class_id(name)), float(t)
            except ValueError:
                c, v = -1, math.nan
            if c not in _ELEMENTS or not 0.0 <= v <= 1.0:
                ap.error(f"--class-threshold {item!r}: expected CLASS=T, an element class and a number in [0, 1]")
            per[c] = v
        keep = set()
        for name in a.keep:
            try:
                c = int(class_id(name))
            except ValueError:
                c = -1
            if c not in _ELEMENTS:
                ap.error(f"--keep {name!r}: expected an element class ({', '.join(ClassId(e).label for e in _ELEMENTS)})")
            keep.add(c)
        if keep and a.choose_thresholds is None:
            ap.error("--keep: only with --choose-thresholds")
        grid = a.choose_thresholds
        if grid is not None and not grid:
            grid = [round(0.05 * k, 2) for k in range(1, 17)]
        if grid and not all(0.0 <= t <= 1.0 for t in grid):
            ap.error("--choose-thresholds: thresholds are numbers in [0, 1]")
        return fit(a.work, a.out, a.threshold, per, grid, frozenset(keep))
    return sweep(a.work, a.model, a.thresholds, not a.reject_only, a.vary)


if __name__ == "__main__":
    sys.exit(main())
