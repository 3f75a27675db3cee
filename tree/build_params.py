"""The recursion's parameters of :func:`tree.build.build_tree`, declared once
(``hollowtree.params``): its keyword defaults and the tree stage's workflow keys
(``pipeline/tree_params.py``, with :func:`~hollowtree.params.like`) are these fields. A
light module (no NumPy): the command line's flags are derived from it.
"""

from __future__ import annotations

from dataclasses import dataclass

from hollowtree.params import Params, param

__all__ = ["BuildParams"]


@dataclass(frozen=True, kw_only=True)
class BuildParams(Params, owner="build_tree"):
    """Parameters of the recursion (Algorithm 1); ``build_tree``'s defaults.

    Parameters
    ----------
    max_depth : int
        The paper's ``d``.
    look_ahead : bool
        A storeys cut that no proposal beats is kept when one of its storeys with a row of
        openings would be cut into bays.
    threshold : float or None
        A split is kept when its score (the split model's probability, or ``xi``) reaches
        this; None = the model's own.
    """

    max_depth: int = param(4, ge=0, doc="maximum depth d of Algorithm 1")
    look_ahead: bool = param(
        True, doc="a storeys split that its own score rejects is kept when one of its storeys would split (into "
                  "bays): a storey cut is judged by what it leads to")
    threshold: float | None = param(
        None, doc="a split is kept when its score (the split model's probability, or xi) >= this; null = the "
                  "model's own")
