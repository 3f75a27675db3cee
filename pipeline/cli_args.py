"""The command line's argument types and the flags derived from the workflow's sections
(one declaration per parameter: the stages' params dataclasses, from which
``pipeline/workflow.py`` derives the sections); ``pipeline/cli.py`` builds the parser with
them."""

from __future__ import annotations

import argparse
from typing import Any

__all__: list[str] = []


def _int(text: str) -> int:
    try:
        return int(text.replace("_", ""))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def _positive_int(text: str) -> int:
    value = _int(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive integer; got {value}")
    return value


def _procedural_points_flag(parser: argparse.ArgumentParser, default: int) -> None:
    """``--procedural-points N`` or ``MIN MAX`` (``train`` and ``fit-split``); read with
    :func:`_procedural_points`."""
    parser.add_argument("--procedural-points", type=_positive_int, nargs="+", default=[default], metavar="N",
                        help="points per procedural site, or MIN MAX: each site's count drawn log-uniformly by "
                             f"its seed (scenes.procedural.site_points; default {default:,})")


def _procedural_points(args: argparse.Namespace) -> int | tuple[int, int]:
    """The value of ``--procedural-points``: one count, or a range ``(MIN, MAX)``.

    Raises
    ------
    ConfigError
        If it holds more than two numbers or MIN > MAX.
    """
    from hollowtree.errors import ConfigError

    pts = args.procedural_points
    if len(pts) > 2 or (len(pts) == 2 and pts[0] > pts[1]):
        raise ConfigError(f"--procedural-points takes N or MIN MAX with MIN <= MAX; got {' '.join(map(str, pts))}")
    return pts[0] if len(pts) == 1 else (pts[0], pts[1])


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def _non_negative(text: str) -> float:
    value = _float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative number; got {text}")
    return value


def _stage_flag(parser: argparse.ArgumentParser, section: Any, *keys: str, **kwargs: Any) -> None:
    """The flags ``--key-name`` for the workflow keys ``keys`` of ``section``
    (``pipeline.workflow``): their help, default, type and choices are the section's (one
    declaration: the stage's params dataclass); their bounds are checked with the
    section's (:func:`_section`). Not given = the section's default."""
    for key in keys:
        _one_flag(parser, section, key, **kwargs)


def _one_flag(parser: argparse.ArgumentParser, section: Any, key: str, **kwargs: Any) -> None:
    import typing

    field = section.model_fields[key]
    kinds = [typing.get_args(a)[0] if typing.get_origin(a) is typing.Annotated else a
             for a in (typing.get_args(field.annotation) or (field.annotation,)) if a is not type(None)]
    choices = typing.get_args(field.annotation) if typing.get_origin(field.annotation) is typing.Literal else None
    _flag(parser, key, field.description or "", field.default, kinds, choices, **kwargs)


def _param_flag(parser: argparse.ArgumentParser, params: type, *keys: str, **kwargs: Any) -> None:
    """The flags ``--key-name`` for the fields ``keys`` of the params dataclass ``params``
    (``hollowtree.params``): their help, default, type and choices are the field's; their
    bounds are checked by the dataclass. Not given = the field's default."""
    from hollowtree.params import specs

    declared = {s.name: s for s in specs(params)}
    for key in keys:
        spec = declared[key]
        _flag(parser, key, spec.rule.doc, spec.default, list(spec.kinds), spec.rule.choices, **kwargs)


def _flag(parser: argparse.ArgumentParser, key: str, doc: str, default: Any, kinds: list[Any],
          choices: tuple[Any, ...] | None, **kwargs: Any) -> None:
    """``--key-name``, not given = None: ``doc`` and the default as its help."""
    text = doc.replace("%", "%%")
    if default is not None and not isinstance(default, (bool, list, tuple)):
        d = default
        text += f" (default {d:,})" if isinstance(d, int) else f" (default {d:g})" if isinstance(d, float) else f" (default {d})"
    if choices is not None:
        kwargs.setdefault("choices", list(choices))
    elif kinds in ([int], [float]):
        kwargs.setdefault("type", _int if kinds == [int] else _float)
    parser.add_argument(f"--{key.replace('_', '-')}", dest=key, default=None, help=text, **kwargs)


def _workers_flag(parser: argparse.ArgumentParser) -> None:
    """``--workers``, with the workflow's default (``cluster.workers``)."""
    from hollowtree.pipeline.workflow import ClusterSection

    n = ClusterSection.model_fields["workers"].default
    parser.add_argument("--workers", type=_positive_int, default=n, help=f"local cluster workers (default {n})")


def _cluster_args(parser: argparse.ArgumentParser) -> None:
    """Where a step command's tasks run, and its progress bars."""
    parser.add_argument("--scheduler", help="Dask scheduler address; 'sync' runs in this process (default: a local "
                                            "cluster, or this process for a store of under cluster.in_process_below "
                                            "input points)")
    _workers_flag(parser)
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def _set_flag(parser: argparse.ArgumentParser, stage: str) -> None:
    parser.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                        help=f"any key of the workflow's {stage} section (docs/workflows.md), the value read as "
                             f"YAML; repeatable")


def _section(section: Any, args: argparse.Namespace, stage: str, extra: dict[str, Any] | None = None) -> Any:
    """The workflow section ``section`` from the flags given and ``--set KEY=VALUE``,
    validated by the section itself (one line, exit 2, when a value is wrong)."""
    import yaml
    from pydantic import ValidationError

    from hollowtree.errors import ConfigError

    values = {k: getattr(args, k) for k in section.model_fields if getattr(args, k, None) is not None}
    values.update(extra or {})
    for item in args.sets:
        key, sep, text = item.partition("=")
        key = key.strip().removeprefix(f"{stage}.")
        if not sep or key not in section.model_fields:
            raise ConfigError(f"--set {item}: expected KEY=VALUE with KEY a key of the workflow's {stage} section "
                              f"({', '.join(section.model_fields)})")
        try:
            values[key] = yaml.safe_load(text)
        except yaml.YAMLError:
            raise ConfigError(f"--set {item}: the value is not YAML") from None
    try:
        return section(**values)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(x) for x in err["loc"])
        got = f" (got {err['input']!r})" if "input" in err and not isinstance(err["input"], dict) else ""
        raise ConfigError(f"{stage}.{where}: {err['msg'].removeprefix('Value error, ')}{got}") from None


def _tile_size(text: str) -> float | None:
    return None if text.strip().lower() == "auto" else _float(text)


def _bbox(text: str) -> tuple[float, float, float, float]:
    parts = text.split(",")
    if len(parts) != 4:
        raise argparse.ArgumentTypeError(f"expected XMIN,YMIN,XMAX,YMAX; got {text!r}")
    vals = tuple(_float(p) for p in parts)
    return vals  # type: ignore[return-value]


def _int_list(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in text.split(",") if p.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected tile ids like 0,1,5; got {text!r}") from None


def _units(text: str | None) -> float | str | None:
    """``--units``: a number (metres per unit) or a unit's name, as ``IngestParams`` takes it."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        return text
