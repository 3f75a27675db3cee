"""The docs as reference (issue 46): generated tables current, relative links valid, sizes
within bounds, no clock times. Fast: reads files and JSON, runs no pipeline."""

from __future__ import annotations

import importlib.util
import io
import re
import tokenize
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
CODE_DIRS = ("hollowtree", "tiling", "primitives", "scenes", "hollownet", "tree", "pipeline", "benchmarks", "tests")
CLOCK = re.compile(r"\b\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}|\bUTC\b")


@pytest.fixture(scope="module")
def report():
    spec = importlib.util.spec_from_file_location("hollowtree_docs_report", REPO / "benchmarks" / "report.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _markdown() -> list[Path]:
    return [REPO / "README.md", REPO / "CHANGELOG.md", *sorted(DOCS.rglob("*.md"))]


def test_generated_tables_are_current(report):
    assert report.stale() == [], "generated tables out of date: run python benchmarks/report.py"
    assert report.main(["--check"]) == 0


def test_every_generator_is_used_and_render_is_idempotent(report):
    used = {m.group(1) for p in report.doc_files() for m in report.BEGIN.finditer(p.read_text())}
    assert used == set(report.GENERATORS)
    text = "before\n<!-- generated: small -->\nstale table\n<!-- end generated -->\nafter\n"
    new = report.render(text, {})
    assert "stale table" not in new
    assert new.startswith("before\n<!-- generated: small -->\n| scan |")
    assert new.endswith("<!-- end generated -->\nafter\n")
    assert report.render(new, {}) == new


def test_per_class_view_of_a_validation_variant_adds_up_its_runs(report, capsys):
    import json

    assert report.main(["--classes", "tree-v45"]) == 0
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("| tree-v45 |")][0]
    cells = [c.strip() for c in line.strip("|").split("|")]
    domes = sum(json.loads((report.RESULTS / f"generalize-{row}-tree-v45{suf}.json").read_text())
                ["totals"]["tree"]["dome"]["found"]
                for row in ("val", "val-4m", "val-density-10m", "val-10m-b", "val-domes")
                for suf in ("", "-seed1", "-seed2"))
    assert cells[1] == "3"
    assert cells[3].startswith(f"{domes / 3:.1f} / ")
    with pytest.raises(SystemExit) as e:
        report.main(["--classes", "no-such-variant"])
    assert e.value.code == 2
    assert "'no-such-variant' is not a variant of VAL_SEEDS" in capsys.readouterr().err


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _strip_code(text: str) -> str:
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M).splitlines():
        m = re.match(r"#{1,6} (.*)", line)
        if m:
            s = _slug(m.group(1))
            n = seen.get(s, 0)
            seen[s] = n + 1
            out.add(s if n == 0 else f"{s}-{n}")
    return out


def test_relative_links_resolve():
    bad = []
    for path in _markdown():
        for target in re.findall(r"\]\(([^)\s]+)\)", _strip_code(path.read_text())):
            if re.match(r"[a-z]+:", target):
                continue
            file, _, anchor = target.partition("#")
            dest = (path.parent / file).resolve() if file else path
            if not dest.exists():
                bad.append(f"{path.relative_to(REPO)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                bad.append(f"{path.relative_to(REPO)}: {target} (no such heading)")
    assert not bad, "\n".join(bad)


def test_sizes():
    files = [p for p in DOCS.rglob("*") if p.is_file()]
    pages = {p.relative_to(REPO).as_posix(): p.stat().st_size for p in files if p.suffix != ".png"}
    assert sum(pages.values()) < 150_000, pages
    assert max(pages.values()) < 40_000, pages
    # screenshots (docs/img/, e.g. docs/view.md's): a budget of their own
    images = {p.relative_to(REPO).as_posix(): p.stat().st_size for p in files if p.suffix == ".png"}
    assert all(p.startswith("docs/img/") for p in images), images
    assert max(images.values(), default=0) < 300_000, images
    assert (REPO / "README.md").stat().st_size < 10_000


def test_no_clock_times_in_docs():
    bad = [f"{p.relative_to(REPO)}:{i}: {line.strip()}" for p in _markdown()
           for i, line in enumerate(p.read_text().splitlines(), 1) if CLOCK.search(line)]
    assert not bad, "\n".join(bad)


def test_no_clock_times_in_code_comments():
    bad = []
    for d in CODE_DIRS:
        for path in sorted((REPO / d).rglob("*.py")):
            try:
                tokens = list(tokenize.generate_tokens(io.StringIO(path.read_text()).readline))
            except (tokenize.TokenError, SyntaxError):  # pragma: no cover - a file being edited
                continue
            for tok in tokens:
                comment = tok.type == tokenize.COMMENT or (
                    tok.type == tokenize.STRING and tok.string.lstrip("rbuRBU").startswith(('"""', "'''")))
                if comment and CLOCK.search(tok.string):
                    bad.append(f"{path.relative_to(REPO)}:{tok.start[0]}")
    assert not bad, bad
