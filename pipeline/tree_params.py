"""The tree stage's parameters, declared once (``hollowtree.params``):
:class:`TreeStageParams`, run by ``pipeline/tree_stage.py``. A light module (no NumPy; of
the tree only ``tree/build_params.py``, whose ``max_depth``, ``look_ahead`` and
``threshold`` it passes on): the workflow's ``tree`` section and the command line's flags
are derived from these fields.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from hollowtree.errors import ConfigError
from hollowtree.params import Params, like, param
from hollowtree.tree.build_params import BuildParams

__all__ = ["DECISIONS", "DEVICES", "MIN_GROUP_SAMPLE", "TreeStageParams"]

#: How a node's proposal is kept (``TreeStageParams.decision``).
DECISIONS = ("split-model", "energy")
#: Where HollowNet runs (``tree.device``): ``auto`` is CUDA where the worker's torch sees a
#: GPU, else the CPU.
DEVICES = ("cpu", "cuda", "auto")
#: The smallest sample a large element group's tree is built on (``max_group_points``).
MIN_GROUP_SAMPLE = 1000


@dataclass(frozen=True, kw_only=True)
class TreeStageParams(Params, owner="tree"):
    """Parameters of the tree stage.

    Parameters
    ----------
    max_depth, look_ahead, threshold
        The recursion's (``tree.build_params.BuildParams``), passed on to
        ``tree.build.build_tree``.
    decision : str
        ``"split-model"`` (the learned split model, ``tree/data/split-v1.json``) or
        ``"energy"`` (the paper's ``xi = w . e``, ``tree/data/energy-v1.json``).
    batch_points : int
        Points per task (small segments are batched; a larger segment is one task); more
        where the largest would otherwise hold over 3x the median task's points
        (``pipeline.tree_stage.plan_batches``).
    weights : str or None
        HollowNet weights; None = the shipped default.
    split_model : str or None
        The split model's JSON (``hollowtree fit-split --out``); None = the shipped
        ``tree/data/split-v1.json``.
    seed : int
        Segment ``g`` builds its tree with ``SeedSequence([seed, g])``.
    roof_min_height : float or None
        A leaf classed ground or roof is roof when its median height above the local
        ground (``tree/ground.py``) is at least this many metres, else ground; None keeps
        HollowNet's class.
    max_group_points : int
        An element group with more points (a ground plane of a large scan can hold 40 %
        of it) builds its tree on a seeded random sample of about this many points, and
        each of its points takes the labels of its nearest sampled point, so a task's
        memory follows this bound rather than the scan; 0 = never sample.
    pillar_max_height : float or None
        A part HollowNet calls pillar that is taller than this many metres is a minaret
        (``tree/tall.py``: HollowNet cannot see size); None (the default) keeps HollowNet's
        class: 10 m, a rule from the five paper sites, lowered the validation F1 sum.
    verify : bool
        Run the element check (``tree/verify.py``) on every element instance after the merge.
    verify_model : str or None
        The element check's JSON; None = the shipped ``tree/data/verify-v3.json``.
    other_max_base, other_max_size : float or None
        A part HollowNet calls other (clutter) whose lowest point is more than
        ``other_max_base`` metres above the local ground, or that is larger than
        ``other_max_size`` metres along x, y or z, takes its next most probable class
        (``tree.tall.not_clutter``); None turns that test off.
    """

    max_depth: int = like(BuildParams, "max_depth")
    look_ahead: bool = like(BuildParams, "look_ahead")
    decision: str = param(
        "split-model", choices=DECISIONS,
        doc="how a node's best proposal is chosen and kept: the learned split model (tree/data/split-v1.json) or "
            "the paper's energy xi = w . e (tree/data/energy-v1.json)")
    threshold: float | None = like(BuildParams, "threshold")
    batch_points: int = param(200_000, ge=1, doc="points per tree task (small segments are batched)")
    weights: str | None = param(None, doc="HollowNet weights file; null = the shipped default")
    split_model: str | None = param(
        None, doc="split model file (written by hollowtree fit-split); null = the shipped tree/data/split-v1.json")
    seed: int = param(0, doc="segment g builds its tree with seed [seed, g]")
    roof_min_height: float | None = param(
        1.5, ge=0, doc="a part classed ground or roof is roof when its median height above the local ground is at "
                       "least this (m); null = HollowNet's class as it is")
    max_group_points: int = param(
        300_000, ge=0,
        check=lambda v: None if v == 0 or v >= MIN_GROUP_SAMPLE else
        f"must be 0 (never sample) or at least {MIN_GROUP_SAMPLE}",
        doc="an element group with more points builds its tree on a seeded sample of this many (0 or at least "
            "1000); its points take their nearest sampled point's labels (bounded memory); 0 = never sample")
    pillar_max_height: float | None = param(
        None, gt=0,
        doc="a part HollowNet calls pillar taller than this (m) is a minaret unless its footprint is flat, a "
            "minaret instance not taller a pillar, a dome instance taller and over 1.5 times as tall as wide a "
            "minaret (HollowNet cannot see size); null (default) = HollowNet's class")
    other_max_base: float | None = param(
        2.0, gt=0,
        doc="a part HollowNet calls other (clutter) whose lowest point is more than this (m) above the local "
            "ground takes its next most probable class (clutter stands on the ground; a dome on its drum looks "
            "like a bush to HollowNet); null = no such test")
    other_max_size: float | None = param(
        15.0, gt=0,
        doc="a part HollowNet calls other (clutter) larger than this (m) along x, y or z takes its next most "
            "probable class (training trees are at most 12 m); null = no such test")

    verify: bool = param(
        True, doc="the element check (tree/verify.py): a learned decision on every element instance after the "
                   "merge, from its class, score, points, box and height above the ground; an instance it does not "
                   "believe becomes other, or takes the element class it believes")
    verify_model: str | None = param(
        None, doc="the element check's file (benchmarks/fit_verify.py); null = the shipped tree/data/verify-v3.json")

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("weights", "split_model", "verify_model"):
            path = getattr(self, name)
            if path is not None and not Path(path).is_file():
                raise ConfigError(f"tree.{name}: file {path} does not exist")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
