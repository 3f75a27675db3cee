"""Workflow files: the YAML a user submits, checked completely before anything runs.

A workflow names the input (files, or a synthetic site made on first use), the run store,
every stage's parameters, the cluster and the outputs. The stages' sections (``ingest``,
``coarse``, ``tree``) are derived from the stages' params dataclasses, where each
parameter's default, bounds and description are declared once (``hollowtree.params``);
the step commands' flags are derived from the sections. :func:`load_workflow` parses the
file, applies ``--set key.path=value`` overrides and validates everything with pydantic;
any problem becomes one :class:`WorkflowError` line naming the file, the key path and the
line::

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
from typing import Annotated, Any, Literal, Union

import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    create_model,
    field_validator,
    model_validator,
)

from hollowtree.errors import ConfigError
from hollowtree.params import Spec, specs
from hollowtree.pipeline.tree_params import DEVICES, TreeStageParams
from hollowtree.primitives.coarse_params import CoarseParams
from hollowtree.scenes.scan_params import DEFAULT_POINTS, ScanParams
from hollowtree.tiling.ingest_params import IngestParams

__all__ = ["Workflow", "WorkflowError", "load_workflow", "json_schema", "apply_override", "shipped_workflows"]


class WorkflowError(ConfigError):
    """A workflow file (or an override) that cannot run; the message is one line."""


PosInt = Annotated[int, Field(ge=1)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SynthInput(_Section):
    """A synthetic scan made by ``hollowtree synth`` the first time the workflow runs."""

    site: str = Field("wazir_khan", description="site or test scene name (hollowtree synth)")
    points: PosInt = Field(DEFAULT_POINTS, description="aim at about this many points")
    seed: int = Field(ScanParams.seed, description="scanner seed")
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


# ------------------------------------------------------------ the stages' sections
def _annotation(spec: Spec) -> Any:
    """The pydantic type of a stage parameter: its field's type with its rule's bounds and
    choices (``hollowtree.params``)."""
    rule = spec.rule

    def scalar(kind: Any) -> Any:
        if kind is float:
            return Annotated[float, Field(allow_inf_nan=False, **rule.bounds)]
        if kind is int and rule.bounds:
            return Annotated[int, Field(**rule.bounds)]
        if kind is str and rule.choices is not None:
            return Literal[rule.choices]
        return kind

    alts = [(tuple[(scalar(k[1]),) * k[2]] if k[2] else Annotated[list[scalar(k[1])], Field(min_length=1)])
            if isinstance(k, tuple) else scalar(k) for k in spec.kinds]
    ann = Union.__getitem__((*alts, None) if spec.none_ok else tuple(alts))  # X | Y | ... of a list
    if rule.check is None:
        return ann
    check = rule.check

    def checked(v: Any) -> Any:
        if v is not None and (problem := check(v)) is not None:
            raise ValueError(problem)
        return v

    return Annotated[ann, AfterValidator(checked)]


def _section(name: str, params: type, doc: str, extra: dict[str, tuple[str | None, Any, Any]] | None = None) -> Any:
    """The workflow section ``name`` of the stage whose parameters are the dataclass
    ``params``: one key per declared workflow parameter, with its default, bounds, choices
    and description. ``extra``: keys the stage's parameters do not hold, as ``key:
    (the key it follows or None for first, type, Field)``."""
    extra = extra or {}
    fields: dict[str, Any] = {k: (t, f) for k, (after, t, f) in extra.items() if after is None}
    for spec in specs(params):
        if spec.rule.workflow:
            default = list(spec.default) if isinstance(spec.default, tuple) and spec.kinds[0][2] is None \
                else spec.default
            fields[spec.name] = (_annotation(spec), Field(default, description=spec.rule.doc))
        fields.update({k: (t, f) for k, (after, t, f) in extra.items() if after == spec.name})
    return create_model(name, __base__=_Section, __doc__=doc, __module__=__name__, **fields)


IngestSection = _section("IngestSection", IngestParams,
                         "``hollowtree ingest`` parameters (tiling/ingest.py ``IngestParams``).")
CoarseSection = _section("CoarseSection", CoarseParams,
                         "``hollowtree coarse`` parameters (pipeline/coarse.py ``CoarseParams``).")
TreeSection = _section(
    "TreeSection", TreeStageParams,
    "The hierarchical tree (tree/): ``enabled: false`` stops after the coarse stage.",
    {"enabled": (None, bool, Field(True, description="run the tree + HollowNet stage")),
     "device": ("weights", Literal[DEVICES], Field(
         "cpu", description="where HollowNet runs in each worker: cpu, cuda, or auto (CUDA where the worker's "
                            "torch sees a GPU); not a parameter of the result"))})


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
        # the --set whose path and the error's agree as far as the shorter goes: tree.x=1 for an
        # error at tree.x.y, foo.bar=1 for an unknown section foo
        setby = next((a for a in overrides if _same_branch(a.partition("=")[0].strip().split("."), loc)), None)
        line = None if setby else _line_of(node, loc)
        where = f":{line}" if line is not None else ""
        if setby:
            msg += f" (from --set {setby})"
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        raise WorkflowError(f"{path}{where}: {key or '(top level)'}: {msg}{more}") from None
    if check_files:
        _check_tree_files(wf, path, node, overrides)
    if check_files and wf.input.files:
        for i, f in enumerate(wf.input.files):
            if not Path(f).is_file():
                line = _line_of(node, ["input", "files", i])
                where = f":{line}" if line is not None else ""
                raise WorkflowError(f"{path}{where}: input.files[{i}]: file {f} does not exist")
    return wf


def _same_branch(path: list[str], loc: Sequence[Any]) -> bool:
    """Whether a ``--set`` key path and a validation error's location agree on their
    common length (at least one key)."""
    n = min(len(path), len(loc))
    return n > 0 and [str(x) for x in loc[:n]] == path[:n]


def _check_tree_files(wf: Workflow, path: Path | str, node: Any, overrides: Sequence[str]) -> None:
    """The tree's files, before any stage runs: each named file exists, and the split
    model and element check the run will use are readable (a bad file would otherwise
    stop the run only when the tree stage starts, after ingest and coarse)."""
    t = wf.tree
    for key in ("weights", "split_model", "verify_model"):
        f = getattr(t, key)
        setby = next((a for a in overrides if a.partition("=")[0].strip() == f"tree.{key}"), None)
        line = None if setby else _line_of(node, ["tree", key])
        where = f":{line}" if line is not None else ""
        said = f" (from --set {setby})" if setby else ""
        if f is not None and not Path(f).is_file():
            raise WorkflowError(f"{path}{where}: tree.{key}: file {f} does not exist{said}")
        used = {"split_model": t.decision == "split-model", "verify_model": t.verify}.get(key, False)
        if f is None or not t.enabled or not used:
            continue
        from hollowtree.tree.split import load_split_model
        from hollowtree.tree.verify import load_verify_model

        try:
            (load_split_model if key == "split_model" else load_verify_model)(f)
        except ConfigError as e:
            raise WorkflowError(f"{path}{where}: tree.{key}: {e}{said}") from None


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
