"""Stage parameters, declared once.

Every parameter of a stage is a field of the stage's frozen dataclass, beside its kernel
(``tiling.ingest_plan.IngestParams``, ``primitives.segment.CoarseParams``, ...). The field
holds the default; its :func:`param` metadata holds the rest: what the parameter means and
the values it may take (a :class:`Rule`). :func:`validate` checks a params object against
its rules (one message format for every stage), and ``pipeline/workflow.py`` derives the
workflow's sections, hence their JSON schema and the command line's flags, from the same
fields::

    @dataclass(frozen=True, kw_only=True)
    class ToyParams(Params, owner="toy"):
        k: int = param(16, ge=3, doc="neighbours")
        eps: float | None = param(None, gt=0, doc="radius, metres; null = automatic")

Bounds apply to a number, or to every number of a sequence; a ``check`` adds a rule the
bounds cannot say (it returns what is wrong, or None). The type is the field's
annotation: ``bool``, ``int``, ``float``, ``str`` (``choices``), a ``tuple`` of those, and
``None`` where the annotation allows it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from hollowtree.errors import ConfigError

__all__ = ["Params", "Rule", "Spec", "arg", "check_args", "check_values", "like", "param", "specs", "validate"]

_MISSING: Any = dataclasses.MISSING


@dataclass(frozen=True)
class Rule:
    """What one parameter means and the values it may take.

    Parameters
    ----------
    doc : str
        One line for the workflow's key table, the JSON schema and the flag's help.
    gt, ge, lt, le : int or float or None
        Bounds of a number (of every number of a sequence).
    choices : tuple or None
        The values a string (every string of a sequence) may take.
    check : callable or None
        ``check(value) -> str | None``: what is wrong with a value of the right type
        within the bounds (``"must be 0 or at least 1"``), or None; not called for None.
    workflow : bool
        A key of the workflow's section (and a flag where the command has one); False
        for a setting the stage fixes.
    """

    doc: str
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple[Any, ...] | None = None
    check: Callable[[Any], str | None] | None = None
    workflow: bool = True

    @property
    def bounds(self) -> dict[str, float]:
        """The bounds given, by name (``gt``, ``ge``, ``lt``, ``le``)."""
        return {k: v for k in ("gt", "ge", "lt", "le") if (v := getattr(self, k)) is not None}

    def interval(self, kind: type) -> str:
        """``[0, inf)``-style text of the bounds, numbers written as ``kind``."""
        def num(v: float) -> str:
            return "inf" if v == math.inf else "-inf" if v == -math.inf else str(kind(v))
        low, high = self.ge if self.ge is not None else self.gt, self.le if self.le is not None else self.lt
        return (f"{'[' if self.ge is not None else '('}{num(-math.inf if low is None else low)}, "
                f"{num(math.inf if high is None else high)}{']' if self.le is not None else ')'}")

    def within(self, v: float) -> bool:
        return ((self.gt is None or v > self.gt) and (self.ge is None or v >= self.ge)
                and (self.lt is None or v < self.lt) and (self.le is None or v <= self.le))


def param(default: Any = _MISSING, *, doc: str, gt: float | None = None, ge: float | None = None,
          lt: float | None = None, le: float | None = None, choices: Sequence[Any] | None = None,
          check: Callable[[Any], str | None] | None = None, workflow: bool = True) -> Any:
    """A dataclass field with its default and its :class:`Rule`: the one declaration of a
    stage parameter."""
    rule = Rule(doc=doc, gt=gt, ge=ge, lt=lt, le=le, choices=None if choices is None else tuple(choices),
                check=check, workflow=workflow)
    return dataclasses.field(default=default, metadata={"rule": rule})


def like(cls: type, name: str, default: Any = _MISSING, **changes: Any) -> Any:
    """The field ``name`` of the params class ``cls`` again (its rule and, unless given,
    its default), for a stage that passes it on to that class: declared once, there."""
    f = cls.__dataclass_fields__[name]
    rule = dataclasses.replace(f.metadata["rule"], **changes)
    return dataclasses.field(default=f.default if default is _MISSING else default, metadata={"rule": rule})


@dataclass(frozen=True)
class Spec:
    """One declared parameter of a params class: its field name, default, rule, whether
    None is allowed, and its value types (``bool``, ``int``, ``float``, ``str``, or
    ``(tuple, item type, length or None)``)."""

    name: str
    default: Any
    rule: Rule
    none_ok: bool
    kinds: tuple[Any, ...]


def _kinds(hint: Any) -> tuple[bool, tuple[Any, ...]]:
    args = typing.get_args(hint) if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union \
        else (hint,)
    kinds: list[Any] = []
    for a in args:
        if a is type(None):
            continue
        if typing.get_origin(a) is tuple:
            items = typing.get_args(a)
            variable = len(items) == 2 and items[1] is Ellipsis
            kinds.append((tuple, items[0], None if variable else len(items)))
        else:
            kinds.append(a)
    return type(None) in args, tuple(kinds)


@functools.cache
def specs(cls: type) -> tuple[Spec, ...]:
    """The declared parameters of the params dataclass ``cls``, in field order."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if "rule" in f.metadata:
            none_ok, kinds = _kinds(hints[f.name])
            out.append(Spec(f.name, f.default, f.metadata["rule"], none_ok, kinds))
    return tuple(out)


_ARTICLE = {bool: "a bool", int: "an int", float: "a float", str: "a string"}


def _scalar(kind: type, rule: Rule, v: Any) -> tuple[bool, Any]:
    """Whether ``v`` is a ``kind`` within ``rule``'s bounds and choices, and ``v`` as one."""
    if kind is bool:
        return isinstance(v, bool), v
    if isinstance(v, bool):
        return False, v
    if kind is int:
        ok = isinstance(v, numbers.Integral)
        return ok and rule.within(v), int(v) if ok else v
    if kind is float:
        ok = isinstance(v, numbers.Real) and math.isfinite(v)
        return ok and rule.within(v), float(v) if ok else v
    if kind is str:
        return isinstance(v, str) and (rule.choices is None or v in rule.choices), v
    return isinstance(v, kind), v


def _describe(spec: Spec) -> str:
    """What a value of ``spec`` must be, for the message of a wrong one."""
    def one(kind: Any, plural: bool = False) -> str:
        if kind is str and spec.rule.choices is not None:
            return ", ".join(repr(c) for c in spec.rule.choices) if plural else \
                f"one of {list(spec.rule.choices)}"
        name = (f"{kind.__name__}s" if plural else _ARTICLE.get(kind, kind.__name__))
        return f"{name} in the range {spec.rule.interval(kind)}" if kind in (int, float) and spec.rule.bounds else name

    def seq(kind: tuple[Any, ...]) -> str:
        return f"a sequence of {kind[2]} {one(kind[1], True)}" if kind[2] else \
            f"a non-empty sequence of {one(kind[1], True)}"

    alts = [seq(k) if isinstance(k, tuple) else one(k) for k in spec.kinds]
    return " or ".join(alts + (["None"] if spec.none_ok else []))


def _value(spec: Spec, v: Any) -> tuple[bool, Any]:
    """Whether ``v`` fits ``spec`` (type, bounds, choices), and ``v`` normalised (numbers as
    their kind, sequences as tuples)."""
    if v is None:
        return spec.none_ok, v
    for kind in spec.kinds:
        if isinstance(kind, tuple):
            _, item, n = kind
            if isinstance(v, (str, bytes, Mapping)) or not isinstance(v, Sequence) or len(v) != (n or len(v)) \
                    or not v:
                continue
            got = [_scalar(item, spec.rule, x) for x in v]
            if all(ok for ok, _ in got):
                return True, tuple(x for _, x in got)
        else:
            ok, norm = _scalar(kind, spec.rule, v)
            if ok:
                return True, norm
    return False, v


def check_values(cls: type, values: Mapping[str, Any], owner: str) -> dict[str, Any]:
    """``values`` (a value for every declared parameter of ``cls``) checked against their
    rules and normalised.

    Raises
    ------
    ConfigError
        ``The 'k' parameter of OWNER must be an int in the range [3, inf). Got 2 instead.``
    """
    out = dict(values)
    for spec in specs(cls):
        v = values[spec.name]
        ok, norm = _value(spec, v)
        problem = None if ok else f"must be {_describe(spec)}"
        if ok and norm is not None and spec.rule.check is not None:
            problem = spec.rule.check(norm)
        if problem is not None:
            raise ConfigError(f"The '{spec.name}' parameter of {owner} {problem}. Got {v!r} instead.")
        out[spec.name] = norm
    return out


def arg(kind: type, *, none_ok: bool = False, gt: float | None = None, ge: float | None = None,
        lt: float | None = None, le: float | None = None) -> Spec:
    """The rule of a kernel function's keyword (a number), for :func:`check_args`:
    ``arg(float, gt=0)``."""
    return Spec("", None, Rule(doc="", gt=gt, ge=ge, lt=lt, le=le), none_ok, (kind,))


def check_args(rules: Mapping[str, Spec], func: str, **values: Any) -> None:
    """Check a kernel function's keywords against its table of :func:`arg` rules.

    Raises
    ------
    ConfigError
        ``The 'eps' parameter of FUNC must be a float in the range (0.0, inf). Got 0 instead.``
    """
    for name, value in values.items():
        spec = rules[name]
        if not _value(spec, value)[0]:
            raise ConfigError(f"The '{name}' parameter of {func} must be {_describe(spec)}. Got {value!r} instead.")


def validate(obj: Any, owner: str) -> None:
    """Check a frozen params object against its fields' rules, in place (sequences become
    tuples, integers given for a float become floats)."""
    got = {s.name: getattr(obj, s.name) for s in specs(type(obj))}
    for name, v in check_values(type(obj), got, owner).items():
        if v is not got[name] or type(v) is not type(got[name]):
            object.__setattr__(obj, name, v)


class Params:
    """Base of a stage's frozen params dataclass: its fields are validated on creation, and
    :meth:`from_workflow` reads the workflow's section of the stage.

    A subclass names the stage in its messages: ``class CoarseParams(Params, owner="coarse")``.
    """

    owner: ClassVar[str] = "params"

    def __init_subclass__(cls, owner: str | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if owner is not None:
            cls.owner = owner

    def __post_init__(self) -> None:
        validate(self, self.owner)

    @classmethod
    def from_workflow(cls, section: Any) -> Any:
        """From the workflow's section of the stage (``pipeline.workflow``), which is
        derived from this class: one keyword per declared workflow key."""
        return cls(**{s.name: getattr(section, s.name) for s in specs(cls) if s.rule.workflow})
