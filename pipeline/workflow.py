"""Workflow files: the YAML a user submits, checked completely before anything runs.

A workflow names the input (files, or a synthetic site made on first use), the run store,
every stage's parameters (defaults = the stage commands' defaults), the cluster and the
outputs. :func:`load_workflow` parses the file, applies ``--set key.path=value``
overrides and validates everything with pydantic; any problem becomes one
:class:`WorkflowError` line naming the file, the key path and the line::

    workflows/bad.yaml:7: coarse.epsilonn: unknown key (did you mean 'epsilon'?)

Relative paths in a workflow are relative to the current directory (the way the CLI
reads them), not to the YAML file. ``docs/workflows.md`` documents every field;
``workflows/schema.json`` is the JSON Schema exported from :class:`Workflow`.
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from hollowtree.errors import ConfigError

__all__ = ["Workflow", "WorkflowError", "load_workflow", "json_schema", "apply_override", "shipped_workflows"]


class WorkflowError(ConfigError):
    """A workflow file (or an override) that cannot run; the message is one line."""


PosFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
PosInt = Annotated[int, Field(ge=1)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SynthInput(_Section):
    """A synthetic scan made by ``hollowtree synth`` the first time the workflow runs."""

    site: str = Field("wazir_khan", description="site or test scene name (hollowtree synth)")
    points: PosInt = Field(1_000_000, description="aim at about this many points")
    seed: int = Field(0, description="scanner seed")
    out: str = Field("out/{site}-{points}.laz", description="where the scan is written; {site}, {points}, {seed} are filled in")

    @field_validator("site")
    @classmethod
    def _known_site(cls, v: str) -> str:
        from hollowtree.scenes.sites import scene_names

        names = scene_names()
        if v not in names:
            close = difflib.get_close_matches(v, names, n=1)
            raise ValueError(f"unknown site {v!r}" + (f" (did you mean {close[0]!r}?)" if close else
                                                       f"; known: {', '.join(names)}"))
        return v

    def path(self) -> Path:
        return Path(self.out.format(site=self.site, points=self.points, seed=self.seed))


class InputSection(_Section):
    """Exactly one of ``files`` and ``synth``."""

    files: list[str] = Field(default_factory=list, description="LAS/LAZ/PLY/E57 files of one registered site")
    synth: SynthInput | None = Field(None, description="make a synthetic scan instead of reading files")

    @model_validator(mode="after")
    def _one_source(self) -> InputSection:
        if bool(self.files) == (self.synth is not None):
            raise ValueError("give exactly one of input.files and input.synth")
        return self

    def paths(self) -> list[Path]:
        return [self.synth.path()] if self.synth is not None else [Path(f) for f in self.files]


class IngestSection(_Section):
    """``hollowtree ingest`` parameters (tiling/ingest.py ``IngestParams``)."""

    tile_size: PosFloat | None = Field(None, description="tile core side, metres; null = about tile_points points per tile")
    tile_points: PosInt = Field(2_000_000, description="target points per tile for the automatic tile size")
    buffer: NonNegFloat = Field(2.0, description="buffer width, metres")
    voxel: PosFloat | None = Field(None, description="keep one point per voxel of this size, metres; null = all")
    bbox: tuple[float, float, float, float] | None = Field(None, description="only tiles meeting [xmin, ymin, xmax, ymax]")
    tiles: list[Annotated[int, Field(ge=0)]] | None = Field(None, description="only these tile ids")
    chunk_size: PosInt = Field(1_000_000, description="records per map task")
    units: PosFloat | str | None = Field(
        None, description="metres per coordinate unit of the inputs (0.3048) or a unit's name (m, ft, us-ft); "
                          "null = the linear unit of their CRS, metres where they have none")

    @field_validator("units")
    @classmethod
    def _unit_known(cls, v: float | str | None) -> float | str | None:
        from hollowtree.tiling.readers import UNIT_METRES

        if isinstance(v, str) and v.lower() not in UNIT_METRES:
            raise ValueError(f"{v!r} is not a unit this knows ({', '.join(sorted(UNIT_METRES))}); give metres per unit")
        return v


class CoarseSection(_Section):
    """``hollowtree coarse`` parameters (pipeline/coarse.py ``CoarseParams``)."""

    k: Annotated[int, Field(ge=3)] = Field(16, description="neighbours of the PCA normals")
    epsilon: PosFloat = Field(0.03, description="RANSAC distance, metres")
    alpha: Annotated[float, Field(gt=0, lt=90)] = Field(20.0, description="RANSAC normal angle, degrees")
    cluster_epsilon: PosFloat | None = Field(None, description="RANSAC bitmap cell, metres; null = max(0.15, 2/3 x the automatic eps)")
    min_support: PosInt = Field(1000, description="smallest primitive, points")
    probability: Annotated[float, Field(gt=0, lt=1)] = Field(0.01, description="accepted chance of missing a primitive")
    shapes: list[Literal["plane", "sphere", "cylinder", "cone", "torus"]] = Field(
        ["plane", "sphere", "cylinder", "cone"], description="primitive types to look for")
    eps: PosFloat | None = Field(None, description="DBSCAN radius, metres; null = 9 x the scan's 25 % 8-NN spacing")
    min_samples: PosInt = Field(10, description="DBSCAN core threshold")
    free_segments: bool = Field(True, description="cluster the points no primitive explains into free segments too")
    free_min_points: PosInt = Field(200, description="smallest free segment, points")
    seed: int = Field(0, description="base seed; tile t uses [seed, t]")
    block_points: Annotated[int, Field(ge=0)] = Field(
        2_200_000, description="tiles with more points are segmented in blocks of at most this many, each a task; "
                               "0 = never")
    block_margin: PosFloat | None = Field(
        None, description="context around a block, metres; null = min(ingest buffer, 2 x eps)")
    sparse_factor: Annotated[float, Field(ge=0)] = Field(
        2.0, description="unsegmented points at least this many times sparser than the scan are segmented once "
                         "more with RANSAC and DBSCAN distances x (2 x this); 0 = one pass")
    group_gap: Annotated[float, Field(ge=0)] = Field(
        0.6, description="segments (not large planes) whose points come this close, metres, are one element "
                         "group for the tree; 0 = every segment alone")
    group_min_contacts: PosInt = Field(3, description="contacts two segments need to be grouped")
    group_max_plane: PosFloat = Field(
        6.0, description="planes wider than this in x-y, metres (ground, roofs, facades), are not grouped with "
                         "their neighbours (but see group_set_in), nor free segments wider than 3 x this")
    group_set_in: Annotated[float, Field(ge=0)] = Field(
        1.5, description="a segment that touches a large wall and lies within this many metres of its plane "
                         "(an arch's jambs and intrados in an arcade's face) joins that wall; 0 = never")
    group_stack: Annotated[float, Field(ge=0)] = Field(
        1.0, description="groups stacked one on another (the upper starts at most this many metres above the "
                         "lower's top, footprints overlapping by 70 %: a minaret's stages) are one group; 0 = never")


#: The smallest sample a large element group's tree is built on (tree.max_group_points).
MIN_GROUP_SAMPLE = 1000


class TreeSection(_Section):
    """The hierarchical tree (tree/): ``enabled: false`` stops after the coarse stage."""

    enabled: bool = Field(True, description="run the tree + HollowNet stage")
    max_depth: Annotated[int, Field(ge=0)] = Field(3, description="maximum depth d of Algorithm 1")
    look_ahead: bool = Field(
        True, description="a storeys split that its own score rejects is kept when one of its storeys would split (into bays): a storey cut is judged by what it leads to")
    decision: Literal["split-model", "energy"] = Field(
        "split-model", description="how a node's best proposal is chosen and kept: the learned split model (tree/data/split-v1.json) or the paper's energy xi = w . e (tree/data/energy-v1.json)")
    threshold: float | None = Field(None, description="a split is kept when its score (the split model's probability, or xi) >= this; null = the model's own")
    batch_points: PosInt = Field(200_000, description="points per tree task (small segments are batched)")
    weights: str | None = Field(None, description="HollowNet weights file; null = the shipped default")
    device: Literal["cpu", "cuda", "auto"] = Field(
        "cpu", description="where HollowNet runs in each worker: cpu, cuda, or auto (CUDA where the worker's torch sees a GPU); not a parameter of the result")
    split_model: str | None = Field(
        None, description="split model file (written by hollowtree fit-split); null = the shipped tree/data/split-v1.json")
    seed: int = Field(0, description="segment g builds its tree with seed [seed, g]")
    roof_min_height: Annotated[float, Field(ge=0)] | None = Field(
        1.5, description="a part classed ground or roof is roof when its median height above the local ground is at least this (m); null = HollowNet's class as it is")
    max_group_points: Annotated[int, Field(ge=0)] = Field(
        1_000_000, description="an element group with more points builds its tree on a seeded sample of this many (0 or at least 1000); its points take their nearest sampled point's labels (bounded memory); 0 = never sample")

    pillar_max_height: Annotated[float, Field(gt=0)] | None = Field(
        10.0, description="a part HollowNet calls pillar that is taller than this (m) is a minaret unless its footprint is flat, and a minaret instance not taller than this is a pillar (HollowNet cannot see size; its training pillars are 2.5-8 m, its minarets 12-40 m); with it on, a dome instance taller than this and more than 1.5 times as tall as it is wide is a minaret; null = HollowNet's class as it is")

    other_max_base: Annotated[float, Field(gt=0)] | None = Field(
        2.0, description="a part HollowNet calls other (clutter) whose lowest point is more than this (m) above the local ground takes its next most probable class (clutter stands on the ground; a dome on its drum looks like a bush to HollowNet); null = no such test")
    other_max_size: Annotated[float, Field(gt=0)] | None = Field(
        15.0, description="a part HollowNet calls other (clutter) larger than this (m) along x, y or z takes its next most probable class (its largest training clutter, trees, is at most 12 m tall and 11 m wide); null = no such test")

    @field_validator("max_group_points")
    @classmethod
    def _sample_not_tiny(cls, v: int) -> int:
        if 0 < v < MIN_GROUP_SAMPLE:
            raise ValueError(f"must be 0 (never sample) or at least {MIN_GROUP_SAMPLE}")
        return v


class JobqueueSection(_Section):
    """Workers as batch jobs (dask-jobqueue): each job runs ``processes`` workers."""

    system: Literal["slurm", "pbs", "sge", "lsf"] = Field(description="the batch system")
    jobs: PosInt = Field(1, description="jobs to submit")
    cores: PosInt = Field(description="cores per job")
    memory: str = Field(description="memory per job, e.g. 32GiB")
    processes: PosInt = Field(1, description="worker processes per job (the cores and memory are shared)")
    walltime: str = Field("01:00:00", description="time limit per job, HH:MM:SS")
    queue: str | None = Field(None, description="queue or partition")
    account: str | None = Field(None, description="account (project) the jobs are charged to")
    job_extra: list[str] = Field(default_factory=list, description="extra directives, e.g. ['--gres=gpu:1']")
    prologue: list[str] = Field(default_factory=list,
                                description="shell lines before the worker starts, e.g. ['module load python']")
    log_directory: str | None = Field(None, description="folder for the jobs' output files")


class KubernetesSection(_Section):
    """Workers as pods (dask-kubernetes' operator, which must be installed in the cluster)."""

    image: str = Field(description="a container image with hollowtree installed")
    workers: PosInt = Field(2, description="worker pods")
    cpu: float = Field(2.0, gt=0, description="CPUs per worker pod")
    memory: str = Field("8Gi", description="memory per worker pod, e.g. 8Gi")
    namespace: str | None = Field(None, description="namespace; null = the current context's")
    env: dict[str, str] = Field(default_factory=dict, description="environment of the pods (e.g. S3 credentials)")


class ClusterSection(_Section):
    """Where the tasks run: a local cluster (the default), a scheduler address, batch jobs
    (``jobqueue``) or Kubernetes pods (``kubernetes``); at most one of the last three."""

    scheduler: str | None = Field(None, description="Dask scheduler address; null = a local cluster; 'sync' = in process")
    workers: PosInt = Field(2, description="workers of the local cluster")
    in_process_below: int = Field(
        2_000_000, ge=0,
        description="a local run (scheduler null) of a scan with fewer input points runs its tasks in this "
                    "process, with no cluster to start; 0 = always a cluster")
    jobqueue: JobqueueSection | None = Field(None, description="workers as SLURM/PBS/SGE/LSF jobs (dask-jobqueue)")
    kubernetes: KubernetesSection | None = Field(None, description="workers as Kubernetes pods (dask-kubernetes)")

    @model_validator(mode="after")
    def _one_place(self) -> ClusterSection:
        named = [k for k in ("scheduler", "jobqueue", "kubernetes") if getattr(self, k) is not None]
        if len(named) > 1:
            raise ValueError(f"give at most one of cluster.scheduler, cluster.jobqueue and cluster.kubernetes "
                             f"(got {', '.join(named)})")
        return self


class OutputsSection(_Section):
    """What the run writes besides the labels in the store (all optional)."""

    las: str | None = Field(None, description="LAS/LAZ with every input point and its labels")
    parquet: str | None = Field(None, description="folder for the segment and tree tables")
    png: str | None = Field(None, description="top and side views coloured by class")


class Workflow(_Section):
    """A whole run: input -> ingest -> coarse -> tree -> labels -> outputs."""

    version: Literal[1] = Field(1, description="workflow schema version")
    input: InputSection
    store: str = Field(description="run store: a folder path or an fsspec URL (s3://...)")
    ingest: IngestSection = Field(default_factory=IngestSection)
    coarse: CoarseSection = Field(default_factory=CoarseSection)
    tree: TreeSection = Field(default_factory=TreeSection)
    cluster: ClusterSection = Field(default_factory=ClusterSection)
    outputs: OutputsSection = Field(default_factory=OutputsSection)


def json_schema() -> dict[str, Any]:
    """The JSON Schema of a workflow file (``workflows/schema.json``)."""
    return Workflow.model_json_schema()


# ---------------------------------------------------------------------------- loading
def _line_of(node: yaml.Node | None, path: Sequence[str | int]) -> int | None:
    """1-based line of the YAML key or item at ``path``, or of the deepest one present."""
    if node is None:
        return None
    line = node.start_mark.line + 1
    for key in path:
        if isinstance(node, yaml.MappingNode):
            pair = next(((k, v) for k, v in node.value if getattr(k, "value", None) == key), None)
            if pair is None:
                break
            line, node = pair[0].start_mark.line + 1, pair[1]
        elif isinstance(node, yaml.SequenceNode) and isinstance(key, int) and 0 <= key < len(node.value):
            node = node.value[key]
            line = node.start_mark.line + 1
        else:
            break
    return line


def _fields_at(path: Sequence[str | int]) -> list[str]:
    model: Any = Workflow
    for key in path:
        if isinstance(key, int):
            continue
        field = getattr(model, "model_fields", {}).get(key)
        if field is None:
            return []
        ann = field.annotation
        model = next((a for a in getattr(ann, "__args__", (ann,)) if isinstance(a, type) and issubclass(a, BaseModel)), None)
        if model is None:
            return []
    return list(getattr(model, "model_fields", {}))


def _message(err: dict[str, Any]) -> tuple[list[str | int], str]:
    loc = [p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-after"))]
    kind = err["type"]
    if kind == "extra_forbidden":
        close = difflib.get_close_matches(str(loc[-1]), _fields_at(loc[:-1]), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        return loc, f"unknown key{hint}"
    if kind == "missing":
        return loc, "required key is missing"
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    got = err.get("input")
    if kind not in ("model_type",) and not isinstance(got, (dict, list)):
        msg += f" (got {got!r})"
    return loc, msg


def apply_override(data: dict[str, Any], assignment: str) -> None:
    """Apply one ``key.path=value`` (value parsed as YAML) to the raw workflow mapping."""
    if "=" not in assignment:
        raise WorkflowError(f"--set {assignment}: expected key.path=value")
    key, _, text = assignment.partition("=")
    parts = [p for p in key.strip().split(".") if p]
    if not parts:
        raise WorkflowError(f"--set {assignment}: empty key")
    try:
        value = yaml.safe_load(text) if text.strip() else None
    except yaml.YAMLError as exc:
        raise WorkflowError(f"--set {assignment}: value is not valid YAML ({exc.problem})") from None
    node = data
    for p in parts[:-1]:
        nxt = node.get(p)
        if nxt is None:
            nxt = node[p] = {}
        if not isinstance(nxt, dict):
            raise WorkflowError(f"--set {assignment}: {p} is not a section")
        node = nxt
    node[parts[-1]] = value


def load_workflow(path: str | Path, overrides: Sequence[str] = (), *, check_files: bool = True) -> Workflow:
    """Read, override and validate a workflow file.

    Raises
    ------
    WorkflowError
        One line: ``FILE:LINE: key.path: problem``.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise WorkflowError(f"{path}: workflow file does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise WorkflowError(f"{path}: cannot be read ({exc})") from None
    try:
        node = yaml.compose(text)
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f":{mark.line + 1}" if mark is not None else ""
        raise WorkflowError(f"{path}{where}: not valid YAML ({getattr(exc, 'problem', exc)})") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise WorkflowError(f"{path}:1: a workflow is a mapping of sections (input, store, ...)")
    for assignment in overrides:
        apply_override(data, assignment)
    try:
        wf = Workflow.model_validate(data)
    except ValidationError as exc:
        loc, msg = _message(exc.errors()[0])
        key = ".".join(str(p) if isinstance(p, str) else f"[{p}]" for p in loc).replace(".[", "[")
        setby = next((a for a in overrides
                      if [str(x) for x in loc[:len(a.partition("=")[0].split("."))]] == a.partition("=")[0].split(".")), None)
        line = None if setby else _line_of(node, loc)
        where = f":{line}" if line is not None else ""
        if setby:
            msg += f" (from --set {setby})"
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        raise WorkflowError(f"{path}{where}: {key or '(top level)'}: {msg}{more}") from None
    if check_files:
        for key in ("weights", "split_model"):
            f = getattr(wf.tree, key)
            if f is not None and not Path(f).is_file():
                line = _line_of(node, ["tree", key])
                where = f":{line}" if line is not None else ""
                raise WorkflowError(f"{path}{where}: tree.{key}: file {f} does not exist")
    if check_files and wf.input.files:
        for i, f in enumerate(wf.input.files):
            if not Path(f).is_file():
                line = _line_of(node, ["input", "files", i])
                where = f":{line}" if line is not None else ""
                raise WorkflowError(f"{path}{where}: input.files[{i}]: file {f} does not exist")
    return wf


def shipped_workflows() -> Path:
    """The folder of the example workflows: ``workflows/`` of a source checkout, or the
    copy a wheel installs as ``hollowtree/workflows``."""
    repo = Path(__file__).resolve().parents[1] / "workflows"
    if (repo / "local.yaml").is_file():
        return repo
    from importlib.resources import files

    return Path(str(files("hollowtree.workflows").joinpath("local.yaml"))).parent


def schema_text() -> str:
    """``workflows/schema.json`` as written by ``hollowtree run --schema``."""
    return json.dumps(json_schema(), indent=2, sort_keys=True) + "\n"
