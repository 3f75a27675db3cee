"""Workflow files: every shipped one loads, bad ones fail before anything runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hollowtree.pipeline.run import changed_stages
from hollowtree.pipeline.workflow import Workflow, WorkflowError, load_workflow, schema_text

REPO = Path(__file__).resolve().parents[1]
WORKFLOWS = sorted((REPO / "workflows").glob("*.yaml"))


@pytest.mark.parametrize("path", WORKFLOWS, ids=[p.name for p in WORKFLOWS])
def test_shipped_workflows_load(path):
    wf = load_workflow(path, check_files=False)
    assert isinstance(wf, Workflow)
    assert wf.store


def test_shipped_set_is_complete():
    assert {p.name for p in WORKFLOWS} >= {"local.yaml", "laptop.yaml", "cluster.yaml"}


def test_schema_file_is_current():
    assert (REPO / "workflows" / "schema.json").read_text() == schema_text(), (
        "workflows/schema.json is stale: regenerate with `hollowtree run --schema > workflows/schema.json`")
    schema = json.loads(schema_text())
    assert set(schema["properties"]) == set(Workflow.model_fields)


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "wf.yaml"
    p.write_text(text)
    return p


GOOD = """\
input:
  synth: {site: wazir_khan, points: 1000}
store: STORE
coarse:
  epsilon: 0.03
"""


@pytest.mark.parametrize(("text", "overrides", "expected"), [
    (GOOD.replace("  epsilon: 0.03", "  epsilonn: 0.03"), [],
     r"wf.yaml:5: coarse.epsilonn: unknown key \(did you mean 'epsilon'\?\)"),
    (GOOD.replace("  epsilon: 0.03", "  epsilon: fast"), [], r"wf.yaml:5: coarse.epsilon: .*number.*'fast'"),
    (GOOD.replace("  epsilon: 0.03", "  epsilon: -1"), [], r"wf.yaml:5: coarse.epsilon: .*greater than 0.*-1"),
    (GOOD.replace("points: 1000", "points: 0"), [], r"wf.yaml:2: input.synth.points: .*greater than or equal to 1"),
    (GOOD.replace("synth: {site: wazir_khan, points: 1000}", "files: [nope.laz]"), [],
     r"wf.yaml:2: input.files\[0\]: file nope.laz does not exist"),
    (GOOD.replace("store: STORE\n", ""), [], r"wf.yaml:1: store: required key is missing"),
    (GOOD + "clustr: {}\n", [], r"wf.yaml:6: clustr: unknown key \(did you mean 'cluster'\?\)"),
    (GOOD, ["cluster.workers=two"], r"wf.yaml: cluster.workers: .*integer.*\(from --set cluster.workers=two\)"),
    (GOOD, ["ingest.buffer=-2"], r"ingest.buffer: .*greater than or equal to 0.*--set ingest.buffer=-2"),
    (GOOD, ["export.path=x.laz"], r"^\S+wf.yaml: export: unknown key \(from --set export.path=x.laz\)$"),
    (GOOD.replace("synth: {site: wazir_khan, points: 1000}", "synth: {site: atlantis}"), [],
     r"wf.yaml:2: input.synth.site: .*unknown site 'atlantis'"),
    ("input: [\n", [], r"wf.yaml:2: not valid YAML"),
    ("- a\n- b\n", [], r"wf.yaml:1: a workflow is a mapping"),
])
def test_bad_workflows_name_file_key_and_line(tmp_path, text, overrides, expected):
    path = _write(tmp_path, text.replace("STORE", str(tmp_path / "s.zarr")))
    with pytest.raises(WorkflowError, match=expected) as info:
        load_workflow(path, overrides)
    assert "\n" not in str(info.value)


def test_missing_workflow_file(tmp_path):
    with pytest.raises(WorkflowError, match=r"nope.yaml: workflow file does not exist"):
        load_workflow(tmp_path / "nope.yaml")


def test_overrides_apply(tmp_path):
    path = _write(tmp_path, GOOD.replace("STORE", str(tmp_path / "s.zarr")))
    wf = load_workflow(path, ["coarse.epsilon=0.05", "tree.enabled=false", "ingest.bbox=[0, 0, 1, 1]"])
    assert wf.coarse.epsilon == 0.05
    assert wf.tree.enabled is False
    assert wf.ingest.bbox == (0.0, 0.0, 1.0, 1.0)


def test_cli_bad_workflow_exits_2_and_writes_nothing(tmp_path):
    store = tmp_path / "s.zarr"
    path = _write(tmp_path, GOOD.replace("STORE", str(store)).replace("epsilon: 0.03", "epsilon: 0"))
    proc = subprocess.run([sys.executable, "-m", "hollowtree", "run", str(path)],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "coarse.epsilon" in lines[0]
    assert ":5:" in lines[0]
    assert not store.exists()
    assert list(tmp_path.iterdir()) == [path]


def test_changed_stages_names_the_first_changed_stage_and_all_after():
    base = {"ingest": {"voxel": None}, "coarse": {"k": 16}, "tree": {"max_depth": 3}, "labels": {}}
    assert changed_stages(base, base) == ([], [])
    assert changed_stages(None, base) == ([], [])
    redo, diffs = changed_stages(base, {**base, "tree": {"max_depth": 4}})
    assert redo == ["tree", "labels"]
    assert diffs == ["tree.max_depth: 3 -> 4"]
    redo, _ = changed_stages(base, {**base, "ingest": {"voxel": 0.05}})
    assert redo == ["ingest", "coarse", "tree", "labels"]


def test_tiny_tree_sample_is_refused(tmp_path):
    path = _write(tmp_path, GOOD.replace("STORE", str(tmp_path / "s.zarr")))
    with pytest.raises(WorkflowError, match="tree.max_group_points"):
        load_workflow(path, ["tree.max_group_points=5"])
    assert load_workflow(path, ["tree.max_group_points=0"]).tree.max_group_points == 0


def test_tree_decision_is_checked(tmp_path):
    path = _write(tmp_path, GOOD.replace("STORE", str(tmp_path / "s.zarr")))
    assert load_workflow(path).tree.decision == "split-model"
    assert load_workflow(path, ["tree.decision=energy"]).tree.decision == "energy"
    with pytest.raises(WorkflowError, match="tree.decision"):
        load_workflow(path, ["tree.decision=coin"])


def test_init_writes_the_shipped_workflows_and_keeps_a_users_files(tmp_path, capsys):
    from hollowtree.pipeline.cli import main

    target = tmp_path / "mine"
    assert main(["init", str(target)]) == 0
    assert sorted(p.name for p in target.iterdir()) == ["cluster.yaml", "laptop.yaml", "local.yaml", "schema.json"]
    assert isinstance(load_workflow(target / "local.yaml", check_files=False), Workflow)
    (target / "local.yaml").write_text("# mine\n")
    capsys.readouterr()
    assert main(["init", str(target)]) == 2
    err = capsys.readouterr().err
    assert "pass --overwrite" in err
    assert len(err.strip().splitlines()) == 1
    assert (target / "local.yaml").read_text() == "# mine\n"  # nothing already written is lost
    assert main(["init", str(target), "--overwrite"]) == 0
    assert (target / "local.yaml").read_text() == (REPO / "workflows" / "local.yaml").read_text()


def test_an_install_is_one_package_named_hollowtree(tmp_path):
    """``pip install --no-deps --target DIR .`` puts only ``hollowtree`` and its dist-info in
    DIR (the console script aside): the subpackages and the example workflows
    (``hollowtree init``, ``evaluate``'s default) live under it, and they import from there."""
    import os
    import subprocess
    import sys

    target = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "-q",
                        "--target", str(target), str(REPO)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    top = {p.name for p in target.iterdir()} - {"bin"}
    assert top == {"hollowtree", next(n for n in top if n.endswith(".dist-info"))}, top
    pkg = target / "hollowtree"
    assert {"pipeline", "tiling", "tree", "hollownet", "primitives", "scenes", "workflows"} <= {
        p.name for p in pkg.iterdir() if p.is_dir()}
    assert {f.name for f in (pkg / "workflows").iterdir()} >= {"local.yaml", "laptop.yaml", "cluster.yaml",
                                                                "schema.json"}
    assert (pkg / "hollownet" / "weights" / "hollownet-v1.pt").is_file()
    code = ("import hollowtree, hollowtree.tree.build as b; from hollowtree.pipeline.workflow import "
            "shipped_workflows; print(b.__file__); print(shipped_workflows()); print(hollowtree.open.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(target)})
    assert out.returncode == 0, out.stderr
    built, flows, api = out.stdout.split()
    assert Path(built).is_relative_to(pkg)
    assert Path(flows) == pkg / "workflows"
    assert api == "hollowtree.api"


@pytest.mark.parametrize(("key", "content", "expected"), [
    ("verify_model", None, r"wf.yaml:7: tree.verify_model: file .*nope.json does not exist"),
    ("verify_model", "{not json", r"wf.yaml:7: tree.verify_model: .*nope.json is not a readable element check"),
    ("split_model", '{"models": 3}', r"wf.yaml:7: tree.split_model: .*nope.json is not a readable split model"),
])
def test_the_trees_files_are_checked_before_any_stage_runs(tmp_path, key, content, expected):
    """A missing or unreadable model file stops the run at once, naming the key and line
    (not when the tree stage starts, after ingest and coarse)."""
    bad = tmp_path / "nope.json"
    if content is not None:
        bad.write_text(content)
    path = _write(tmp_path, GOOD.replace("STORE", str(tmp_path / "s.zarr")) + f"tree:\n  {key}: {bad}\n")
    with pytest.raises(WorkflowError, match=expected) as info:
        load_workflow(path)
    assert "\n" not in str(info.value)
    if content is not None:  # a file the run will not use is not read
        off = "tree.verify=false" if key == "verify_model" else "tree.decision=energy"
        assert getattr(load_workflow(path, [off]).tree, key) == str(bad)
