"""The coarse stage's parameters, declared once (``hollowtree.params``): Efficient
RANSAC's (:class:`RansacParams`, the defaults of :func:`primitives.ransac.efficient_ransac`)
and the stage's (:class:`CoarseParams`, run by ``primitives/segment.py``). A light module
(no NumPy): the workflow's ``coarse`` section and the command line's flags are derived
from these fields.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from hollowtree.errors import ConfigError
from hollowtree.params import Params, arg, like, param

__all__ = ["DBSCAN_ARGS", "DEFAULT_KINDS", "KINDS", "NORMALS_ARGS", "CoarseParams", "RansacParams"]

#: The rules of the keywords of ``primitives/normals.py`` and ``primitives/dbscan.py``
#: (their checks, and the stage's parameters that are passed on to them).
NORMALS_ARGS = {"k": arg(int, ge=3), "radius": arg(float, gt=0, none_ok=True)}
DBSCAN_ARGS = {"eps": arg(float, gt=0), "min_samples": arg(int, ge=1), "k": arg(int, ge=1),
               "factor": arg(float, gt=0), "quantile": arg(float, gt=0, le=1)}
#: Primitive kinds implemented, in the order candidates are generated.
KINDS = ("plane", "sphere", "cylinder", "cone", "torus")
#: Kinds searched by default. Tori are left out: their 4-point minimal sets double the
#: minimal sets the stopping rule asks for (eq. 2), which slows scenes without tori.
DEFAULT_KINDS = ("plane", "sphere", "cylinder", "cone")


@dataclass(frozen=True, kw_only=True)
class RansacParams(Params, owner="RansacParams"):
    """Defaults of :func:`efficient_ransac` for survey-density scans (mm to cm spacing).

    ``efficient_ransac(xyz, normals, **RansacParams().to_dict())`` runs with them.

    Examples
    --------
    >>> p = RansacParams(min_support=500)
    >>> RansacParams.from_dict(p.to_dict()) == p, p.epsilon
    (True, 0.03)
    """

    epsilon: float = param(0.03, gt=0, doc="RANSAC distance, metres")
    alpha_deg: float = param(20.0, gt=0, le=90, doc="RANSAC normal angle, degrees")
    cluster_epsilon: float = param(0.15, gt=0, doc="RANSAC bitmap cell, metres")
    min_support: int = param(200, ge=3, doc="smallest primitive, points")
    probability: float = param(0.01, gt=0, lt=1, doc="accepted chance of missing a primitive")
    shapes: tuple[str, ...] = param(DEFAULT_KINDS, choices=KINDS, doc="primitive types to look for")
    max_iterations: int | None = param(None, ge=1, doc="most candidates drawn; None = the stopping rule alone")

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form whose keys are :func:`efficient_ransac`'s keywords."""
        d = asdict(self)
        d["shapes"] = list(self.shapes)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RansacParams:
        """Inverse of :meth:`to_dict`; unknown keys are errors."""
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ConfigError(f"Unknown RansacParams keys {sorted(unknown)}; valid keys are "
                              f"{sorted(cls.__dataclass_fields__)}.")
        kw = dict(d)
        if "shapes" in kw:
            kw["shapes"] = tuple(kw["shapes"])
        return cls(**kw)


@dataclass(frozen=True, kw_only=True)
class CoarseParams(Params, owner="coarse"):
    """Parameters of the coarse stage.

    Parameters
    ----------
    k : int
        Neighbours of the PCA normals.
    epsilon, alpha, min_support, probability, shapes
        Efficient RANSAC's (:class:`RansacParams`, where their defaults and rules are
        declared; :attr:`ransac` gives them with the bitmap cell); the stage's default
        minimum support is 1000 points (small primitives cost most of the time and the
        tree splits segments further anyway).
    cluster_epsilon : float or None
        RANSAC's bitmap cell; None = max(0.15 m, 2/3 of the automatic eps), computed
        once per store, so sparse far surfaces are not shattered into bitmap islands
        (``RansacParams``' default cell where the kernels are called without a store).
    eps : float or None
        DBSCAN radius (metres); None = ``EPS_FACTOR`` (9) x the 25 % quantile of the
        8-NN spacing over windows of the whole scan (:func:`scan_spacing`), computed once
        for the whole store so every tile uses the same value.
    min_samples : int
        DBSCAN core threshold.
    free_segments : bool
        Also split the points that no primitive explains into DBSCAN clusters ("free"
        segments, primitive code 0), so that small or sparsely scanned elements (a
        minaret whose stages are each below the minimum support, a small dome) still reach
        the tree and HollowNet. The paper leaves these points' fate open; without this
        they stay unsegmented and unlabelled.
    free_min_points, free_min_cells : int
        Free clusters of fewer than ``free_min_points`` points that also span fewer than
        ``free_min_cells`` cells of 0.1 m stay unsegmented (scanner noise, stray points,
        shreds of a surface): a small cluster that spans many cells is a sparsely scanned
        element (:func:`primitives.segment.small_free_clusters`). 0 cells = the count alone.
    seed : int
        Base seed; tile t uses ``SeedSequence([seed, t])``.
    angle_tol_deg, distance_tol, radius_tol : float
        When two tiles' segments that share points are the same primitive: axes/normals
        within ``angle_tol_deg``, positions within ``distance_tol`` metres, radii within
        ``radius_tol`` (relative).
    block_points : int
        A tile with more points is segmented in x-y blocks of at most this many points
        (each with a margin of context around it, each a task of its own), joined like
        tiles, so that a task's memory follows this bound and not the densest spot of the
        scan (a tile near a scanner station can hold several times the average). 0 =
        never. Default 1.8 M: a unit's seconds per point vary about 4x with what it
        holds, and a many-worker run waits for its slowest unit (docs/method.md, "Blocks
        inside a dense tile"). A run lowers it (to an eighth at most) where its tiles
        are uneven, until no task holds much over 3x the median task's points
        (``pipeline.coarse.balanced_block_points``).
    block_margin : float or None
        Context around a block, metres; None = min(the tile buffer, 2 x the DBSCAN eps).
        Dense blocks are small (a 1 M-point block near a station can be 3 x 4 m), so a
        margin as wide as the tile buffer would multiply the points each block processes;
        one eps was measured too narrow (the join missed, adjusted Rand index 0.70 against
        whole tiles), two eps enough (0.9995).
    sparse_factor : float
        Sparse second pass (docs/method.md): the points the first pass leaves unsegmented
        whose spacing (to their 8th-nearest neighbour among all points) is at least this many
        times the scan's (eps / 3) are segmented once more (normals, RANSAC, DBSCAN) with
        RANSAC's epsilon and cell and the DBSCAN eps multiplied by ``2 x sparse_factor``
        and the minimum support divided by its square (at least ``free_min_points``);
        each second-pass segment then joins the first-pass segments of the same primitive
        it touches. 0 = one pass only.
    group_gap : float
        Element groups (docs/method.md): global segments whose points come within this
        many metres of each other (:func:`primitives.group.segment_contacts`) and that
        are not large planes are one element group, the unit the tree splits and
        HollowNet classifies; 0 = every segment is its own group (the paper's reading).
    group_min_contacts : int
        Contacts (voxel representatives within ``group_gap``) two segments need.
    group_max_plane : float
        A plane whose horizontal extent (bounding-box diagonal in x-y) exceeds this many
        metres (ground, roofs, facades) is never grouped with its neighbours, except as below;
        nor is a free segment wider than ``STRIP_FACTOR`` (3) times this (a strip along a
        facade; :func:`primitives.group.large_segments`).
    group_set_in : float
        A segment set in a large wall (it touches a near-vertical large plane, and its
        bounding box lies within this many metres of the plane and inside the plane's box
        grown by as much): the jambs and intrados of an arcade's arches in the arcade's
        face. Such a segment joins that wall (of several, the one it has most contacts
        with) and none of its other neighbours, so the tree cuts the face into bays with
        their intrados, and two walls never join through it; 0 = never (coarse-v2).
    group_stack : float
        Element groups stacked one on another (the upper one starts at most this many
        metres above the top of the lower one, their footprints overlap by 70 % of the
        smaller one and their areas are within 3x; :func:`primitives.group.stacked_pairs`)
        are one group: a minaret's stages, whose joints its balconies hide from every
        station. Groups holding a large segment (plane or free strip) are never stacked.
        0 = never (coarse-v2).
    """

    k: int = param(16, **NORMALS_ARGS["k"].rule.bounds, doc="neighbours of the PCA normals")
    epsilon: float = like(RansacParams, "epsilon")
    alpha: float = like(RansacParams, "alpha_deg")
    cluster_epsilon: float | None = like(
        RansacParams, "cluster_epsilon", None, doc="RANSAC bitmap cell, metres; null = max(0.15, 2/3 x the automatic eps)")
    min_support: int = like(RansacParams, "min_support", 1000)
    probability: float = like(RansacParams, "probability")
    shapes: tuple[str, ...] = like(RansacParams, "shapes")
    eps: float | None = param(None, **DBSCAN_ARGS["eps"].rule.bounds,
                              doc="DBSCAN radius, metres; null = 9 x the scan's 25 % 8-NN spacing")
    min_samples: int = param(10, **DBSCAN_ARGS["min_samples"].rule.bounds, doc="DBSCAN core threshold")
    free_segments: bool = param(True, doc="cluster the points no primitive explains into free segments too")
    free_min_points: int = param(200, ge=1, doc="smallest free segment, points (but see free_min_cells)")
    free_min_cells: int = param(
        50, ge=0, doc="a free cluster under free_min_points is still a segment where it spans at least this many "
                      "0.1 m cells (a sparsely scanned element); 0 = the count alone")
    seed: int = param(0, doc="base seed; tile t uses [seed, t]")
    angle_tol_deg: float = param(10.0, ge=0, workflow=False, doc="same primitive: axes within this, degrees")
    distance_tol: float = param(0.15, ge=0, workflow=False, doc="same primitive: positions within this, metres")
    radius_tol: float = param(0.15, ge=0, workflow=False, doc="same primitive: radii within this, relative")
    block_points: int = param(
        1_800_000, ge=0, doc="tiles with more points are segmented in blocks of at most this many, each a task; "
                             "0 = never")
    block_margin: float | None = param(
        None, gt=0, doc="context around a block, metres; null = min(ingest buffer, 2 x eps)")
    sparse_factor: float = param(
        2.0, ge=0, check=lambda v: None if v == 0 or v >= 1 else "must be 0 or at least 1",
        doc="unsegmented points at least this many times sparser than the scan are segmented once more with "
            "RANSAC and DBSCAN distances x (2 x this); 0 = one pass")
    group_gap: float = param(
        0.6, ge=0, doc="segments (not large planes) whose points come this close, metres, are one element group "
                       "for the tree; 0 = every segment alone")
    group_min_contacts: int = param(3, ge=1, doc="contacts two segments need to be grouped")
    group_max_plane: float = param(
        6.0, gt=0, doc="planes wider than this in x-y, metres (ground, roofs, facades), are not grouped with "
                       "their neighbours (but see group_set_in), nor free segments wider than 3 x this")
    group_set_in: float = param(
        1.5, ge=0, doc="a segment that touches a large wall and lies within this many metres of its plane (an "
                       "arch's jambs and intrados in an arcade's face) joins that wall; 0 = never")
    group_stack: float = param(
        1.0, ge=0, doc="groups stacked one on another (the upper starts at most this many metres above the "
                       "lower's top, footprints overlapping by 70 %: a minaret's stages) are one group; 0 = never")

    @property
    def ransac(self) -> RansacParams:
        """Efficient RANSAC's parameters (the bitmap cell: ``RansacParams``' default while
        ``cluster_epsilon`` is None)."""
        cell = RansacParams.cluster_epsilon if self.cluster_epsilon is None else self.cluster_epsilon
        return RansacParams(epsilon=self.epsilon, alpha_deg=self.alpha, cluster_epsilon=cell,
                            min_support=self.min_support, probability=self.probability, shapes=self.shapes)

    def to_dict(self) -> dict[str, Any]:
        """The form a store records (RANSAC's parameters under ``ransac``, as
        :func:`efficient_ransac`'s keywords)."""
        d = {k: v for k, v in asdict(self).items() if k not in _RANSAC_KEYS}
        return {**d, "ransac": self.ransac.to_dict()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CoarseParams:
        """Inverse of :meth:`to_dict`, also for what older stores recorded."""
        d = dict(data)
        d.setdefault("block_points", 0)  # stores written before blocks existed: tiles whole
        d.setdefault("block_margin", None)
        d.setdefault("group_gap", 0.0)  # stores written before element groups: one group per segment
        d.setdefault("sparse_factor", 0.0)  # stores written before the sparse pass: one pass
        r = d.pop("ransac")
        if d.get("cluster_epsilon") is None and r["cluster_epsilon"] != RansacParams.cluster_epsilon:
            d["cluster_epsilon"] = r["cluster_epsilon"]
        return cls(**d, **{k: r[_RANSAC_KEYS[k]] for k in _RANSAC_KEYS})


#: The fields of :class:`CoarseParams` that are Efficient RANSAC's, and their names there.
_RANSAC_KEYS = {"epsilon": "epsilon", "alpha": "alpha_deg", "min_support": "min_support",
                "probability": "probability", "shapes": "shapes"}


