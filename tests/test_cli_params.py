"""One declaration per parameter: the workflow YAML, the step commands' flags and
``--set`` give the same stage parameters, with the workflow sections' defaults."""

from __future__ import annotations

import pytest

from hollowtree.errors import ConfigError
from hollowtree.pipeline.cli import _section, build_parser
from hollowtree.pipeline.coarse import CoarseParams
from hollowtree.pipeline.tree_stage import TreeStageParams
from hollowtree.pipeline.workflow import CoarseSection, IngestSection, TreeSection, load_workflow
from hollowtree.tiling.ingest import IngestParams

STAGES = {
    "ingest": (IngestSection, IngestParams.from_workflow, ["ingest", "a.laz", "--store", "s.zarr"]),
    "coarse": (CoarseSection, CoarseParams.from_workflow, ["coarse", "s.zarr"]),
    "tree": (TreeSection, TreeStageParams.from_workflow, ["tree", "s.zarr"]),
}


def _cli(stage: str, *flags: str):
    section, convert, argv = STAGES[stage]
    args = build_parser().parse_args([*argv, *flags])
    extra = {"free_segments": False} if getattr(args, "no_free_segments", False) else None
    return convert(_section(section, args, stage, extra))


def _yaml(tmp_path, stage: str, body: str = "{}"):
    (tmp_path / "a.laz").write_bytes(b"")
    wf = tmp_path / "wf.yaml"
    wf.write_text(f"input: {{files: [{tmp_path / 'a.laz'}]}}\nstore: s.zarr\n{stage}: {body}\n")
    section, convert, _ = STAGES[stage]
    return convert(getattr(load_workflow(wf), stage))


@pytest.mark.parametrize("stage", list(STAGES))
def test_no_flag_is_the_workflows_default(tmp_path, stage):
    assert _cli(stage) == _yaml(tmp_path, stage)


@pytest.mark.parametrize(("stage", "flags", "body"), [
    ("ingest", ["--tile-size", "auto", "--voxel", "0.02", "--units", "ft"], "{voxel: 0.02, units: ft}"),
    ("ingest", ["--set", "tile_points=500000", "--bbox", "0,0,10,10"], "{tile_points: 500000, bbox: [0, 0, 10, 10]}"),
    ("coarse", ["--group-gap", "0.3", "--set", "group_stack=0", "--no-free-segments"],
     "{group_gap: 0.3, group_stack: 0, free_segments: false}"),
    ("coarse", ["--epsilon", "0.05", "--set", "coarse.shapes=[plane, sphere]"], "{epsilon: 0.05, shapes: [plane, sphere]}"),
    ("tree", ["--batch-points", "40000", "--set", "look_ahead=false"], "{batch_points: 40000, look_ahead: false}"),
    ("tree", ["--decision", "energy", "--set", "pillar_max_height=null"], "{decision: energy, pillar_max_height: null}"),
])
def test_flags_and_set_equal_the_yaml(tmp_path, stage, flags, body):
    assert _cli(stage, *flags) == _yaml(tmp_path, stage, body)


@pytest.mark.parametrize(("stage", "flags", "message"), [
    ("coarse", ["--set", "nope=1"], "--set nope=1: expected KEY=VALUE with KEY a key of the workflow's coarse section"),
    ("coarse", ["--set", "group_gap=-1"], "coarse.group_gap: Input should be greater than or equal to 0 (got -1)"),
    ("tree", ["--set", "max_group_points=10"], "tree.max_group_points: Value error, must be 0 (never sample) or at least 1000"),
    ("ingest", ["--set", "units=furlong"], "ingest.units"),
])
def test_a_bad_value_is_one_line(stage, flags, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        _cli(stage, *flags)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("stage", list(STAGES))
def test_the_kernels_defaults_are_the_workflows(stage):
    """The stage parameters' own defaults (``CoarseParams()``, used by the kernels' callers
    and the benchmarks) are those of the workflow section, which the CLI help and the JSON
    schema are generated from."""
    section, convert, _ = STAGES[stage]
    params = convert(section())
    assert type(params)() == params
