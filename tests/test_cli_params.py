"""One declaration per parameter: each stage parameter's default, bounds, choices and
description are written once, in the stage's params dataclass (``hollowtree.params``);
the workflow's section, its JSON schema and the step command's flags are derived from
it, and the workflow YAML, the Python API, the flags and ``--set`` give the same
parameters."""

from __future__ import annotations

import pytest
import yaml

from hollowtree.errors import ConfigError
from hollowtree.params import specs
from hollowtree.pipeline.cli import _section, build_parser
from hollowtree.pipeline.coarse import CoarseParams
from hollowtree.pipeline.tree_stage import TreeStageParams
from hollowtree.pipeline.workflow import (
    CoarseSection,
    IngestSection,
    TreeSection,
    WorkflowError,
    json_schema,
    load_workflow,
)
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


PARAMS = {"ingest": IngestParams, "coarse": CoarseParams, "tree": TreeStageParams}


@pytest.mark.parametrize(("stage", "flags", "body", "python"), [
    ("ingest", ["--tile-size", "auto", "--voxel", "0.02", "--units", "ft"], "{voxel: 0.02, units: ft}",
     {"voxel": 0.02, "units": "ft"}),
    ("ingest", ["--set", "tile_points=500000", "--bbox", "0,0,10,10"], "{tile_points: 500000, bbox: [0, 0, 10, 10]}",
     {"tile_points": 500_000, "bbox": [0, 0, 10, 10]}),
    ("coarse", ["--group-gap", "0.3", "--set", "group_stack=0", "--no-free-segments"],
     "{group_gap: 0.3, group_stack: 0, free_segments: false}", {"group_gap": 0.3, "group_stack": 0, "free_segments": False}),
    ("coarse", ["--epsilon", "0.05", "--set", "coarse.shapes=[plane, sphere]"], "{epsilon: 0.05, shapes: [plane, sphere]}",
     {"epsilon": 0.05, "shapes": ["plane", "sphere"]}),
    ("tree", ["--batch-points", "40000", "--set", "look_ahead=false"], "{batch_points: 40000, look_ahead: false}",
     {"batch_points": 40_000, "look_ahead": False}),
    ("tree", ["--decision", "energy", "--set", "pillar_max_height=null"], "{decision: energy, pillar_max_height: null}",
     {"decision": "energy", "pillar_max_height": None}),
])
def test_flags_set_and_python_equal_the_yaml(tmp_path, stage, flags, body, python):
    params = _yaml(tmp_path, stage, body)
    assert _cli(stage, *flags) == params
    assert PARAMS[stage](**python) == params
    assert params.to_dict() == PARAMS[stage](**python).to_dict()  # the same parameters hash


@pytest.mark.parametrize(("stage", "key", "value", "schema_says"), [
    ("coarse", "min_support", 2, "greater than or equal to 3"),
    ("coarse", "alpha", 91, "less than or equal to 90"),
    ("coarse", "sparse_factor", 0.5, "must be 0 or at least 1"),
    ("ingest", "bbox", [0, 0, -1, 1], "must have xmin < xmax"),
    ("tree", "decision", "vote", "'split-model' or 'energy'"),
])
def test_a_bad_value_is_refused_the_same_everywhere(tmp_path, stage, key, value, schema_says):
    """The YAML, ``--set`` and the Python API check a value with the same rule."""
    text = yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()
    with pytest.raises(WorkflowError, match=schema_says):
        _yaml(tmp_path, stage, f"{{{key}: {text}}}")
    with pytest.raises(ConfigError, match=schema_says):
        _cli(stage, "--set", f"{key}={text}")
    with pytest.raises(ConfigError, match=f"The '{key}' parameter of {stage} must"):
        PARAMS[stage](**{key: value})


def _jsonable(value):
    return list(value) if isinstance(value, tuple) else value


def _bounds(prop: dict) -> dict:
    """The bounds a JSON schema property states, as ``hollowtree.params`` names them."""
    names = {"minimum": "ge", "exclusiveMinimum": "gt", "maximum": "le", "exclusiveMaximum": "lt"}
    out = {}
    for node in [prop, *prop.get("anyOf", [])]:
        for n in (node, node.get("items", {})):
            out.update({names[k]: v for k, v in n.items() if k in names})
    return out


@pytest.mark.parametrize("stage", list(STAGES))
def test_the_dataclass_is_the_one_declaration(stage):
    """The JSON schema's section and the step command's flags say what the stage's params
    dataclass declares: key, default, bounds, choices and description, for every key."""
    section, _, argv = STAGES[stage]
    props = json_schema()["$defs"][section.__name__]["properties"]
    declared = [s for s in specs(PARAMS[stage]) if s.rule.workflow]
    workflow_only = {"tree": {"enabled", "device"}}.get(stage, set())
    assert [k for k in section.model_fields if k not in workflow_only] == [s.name for s in declared]
    assert set(props) == {s.name for s in declared} | workflow_only
    sub = next(a for a in build_parser()._subparsers._group_actions if argv[0] in a.choices).choices[argv[0]]
    flags = {a.dest: a for a in sub._actions}
    for spec in declared:
        prop = props[spec.name]
        assert prop["default"] == _jsonable(spec.default), spec.name
        assert prop["description"] == spec.rule.doc, spec.name
        assert _bounds(prop) == spec.rule.bounds, spec.name
        enum = prop.get("enum") or prop.get("items", {}).get("enum")
        assert enum == (list(spec.rule.choices) if spec.rule.choices else None), spec.name
        flag = flags.get(spec.name)
        if flag is not None:  # a flag (the others are --set KEY=VALUE)
            assert flag.default is None, spec.name
            assert flag.help.replace("%%", "%").startswith(spec.rule.doc), spec.name
            d = spec.default
            if d is not None and not isinstance(d, (bool, tuple)):
                shown = f"{d:,}" if isinstance(d, int) else f"{d:g}" if isinstance(d, float) else d
                assert flag.help.endswith(f"(default {shown})"), spec.name
            assert flag.choices == (list(spec.rule.choices) if spec.rule.choices else None), spec.name


@pytest.mark.parametrize(("stage", "flags", "message"), [
    ("coarse", ["--set", "nope=1"], "--set nope=1: expected KEY=VALUE with KEY a key of the workflow's coarse section"),
    ("coarse", ["--set", "group_gap=-1"], "coarse.group_gap: Input should be greater than or equal to 0 (got -1)"),
    ("tree", ["--set", "max_group_points=10"], "tree.max_group_points: must be 0 (never sample) or at least 1000 (got 10)"),
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


def _flags(command: str) -> dict:
    sub = next(a for a in build_parser()._subparsers._group_actions if command in a.choices).choices[command]
    return {a.dest: a for a in sub._actions}


def test_the_synth_flags_are_the_scans_declaration():
    """``hollowtree synth``'s flags and the workflow's ``input.synth`` say what
    ``ScanParams`` declares (and the point count ``DEFAULT_POINTS``)."""
    import inspect

    from hollowtree.scenes.scan_params import DEFAULT_POINTS, ScanParams
    from hollowtree.scenes.synth import synth

    flags = _flags("synth")
    declared = {s.name: s for s in specs(ScanParams)}
    for key in ("seed", "noise", "registration_error"):
        spec, flag = declared[key], flags[key]
        assert flag.default is None, key
        shown = f"{spec.default:,}" if isinstance(spec.default, int) else f"{spec.default:g}"
        assert flag.help == f"{spec.rule.doc} (default {shown})", key
        assert inspect.signature(synth).parameters[key].default == spec.default, key
    assert flags["points"].help.endswith(f"(default {DEFAULT_POINTS:,})")
    props = json_schema()["$defs"]["SynthInput"]["properties"]
    assert (props["points"]["default"], props["seed"]["default"]) == (DEFAULT_POINTS, ScanParams.seed)


def test_the_kernels_take_their_defaults_from_the_declaration():
    """The tree's recursion, the split fit, the HollowNet data sets and training take their
    defaults from the one declaration of each parameter."""
    import dataclasses
    import inspect

    from hollowtree.hollownet.dataset import DatasetParams, labelled_samples
    from hollowtree.hollownet.train import TrainConfig
    from hollowtree.tree.build import build_tree
    from hollowtree.tree.build_params import BuildParams
    from hollowtree.tree.fit_split import proposal_samples

    def defaults(func) -> dict:
        return {k: p.default for k, p in inspect.signature(func).parameters.items()}

    stage = {s.name: s for s in specs(TreeStageParams)}
    for spec in specs(BuildParams):
        assert defaults(build_tree)[spec.name] == spec.default, spec.name
        assert (stage[spec.name].default, stage[spec.name].rule) == (spec.default, spec.rule), spec.name
    assert defaults(proposal_samples)["max_depth"] == BuildParams().max_depth
    data = {s.name: s for s in specs(DatasetParams)}
    train = {s.name: s for s in specs(TrainConfig)}
    for key in ("seed", "variants"):
        assert (train[key].default, train[key].rule) == (data[key].default, data[key].rule), key
    for key in ("seed", "variants", "grid_size", "canonical_yaw"):
        assert defaults(labelled_samples)[key] == data[key].default, key
    assert dataclasses.asdict(TrainConfig().datasets()[0]) == {
        **dataclasses.asdict(DatasetParams()), "n_per_class": TrainConfig().n_train}
