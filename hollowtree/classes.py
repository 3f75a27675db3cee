"""The class vocabulary of hollowtree: the one place where ids and names are defined.

Every module that needs a class id or name imports it from here (``../shared/METHOD.md``,
"Classes"). It sits on the ground floor (``hollowtree/`` itself, below ``tiling/``) so
that every package can import it without an upward arrow.

Examples
--------
>>> int(ClassId.DOME), ClassId.DOME.label
(5, 'dome')
>>> class_id("minaret")
<ClassId.MINARET: 6>
>>> [c.label for c in ELEMENT_CLASSES]
['arch', 'dome', 'minaret', 'pillar']
"""

from __future__ import annotations

from enum import IntEnum

__all__ = [
    "ClassId",
    "CLASS_NAMES",
    "NUM_CLASSES",
    "ELEMENT_CLASSES",
    "PLANAR_CLASSES",
    "class_id",
]


class ClassId(IntEnum):
    """Class ids as stored in ``gt_class`` and in every label array (uint8)."""

    UNCLASSIFIED = 0
    GROUND = 1
    WALL = 2
    ROOF = 3
    ARCH = 4
    DOME = 5
    MINARET = 6
    PILLAR = 7
    OTHER = 8

    @property
    def label(self) -> str:
        """Lower-case name used in files, tables and the CLI."""
        return self.name.lower()


#: Names indexed by id: ``CLASS_NAMES[5] == "dome"``.
CLASS_NAMES: tuple[str, ...] = tuple(c.label for c in ClassId)
NUM_CLASSES: int = len(CLASS_NAMES)
#: Classes whose instances are architectural elements (counted in the paper's Table 1).
ELEMENT_CLASSES: tuple[ClassId, ...] = (ClassId.ARCH, ClassId.DOME, ClassId.MINARET, ClassId.PILLAR)
#: Classes whose instances are connected planar pieces.
PLANAR_CLASSES: tuple[ClassId, ...] = (ClassId.GROUND, ClassId.WALL, ClassId.ROOF)


def class_id(name: str) -> ClassId:
    """Return the :class:`ClassId` called ``name`` (case-insensitive).

    Raises
    ------
    ValueError
        If ``name`` is not in the vocabulary; the message lists the known names.
    """
    try:
        return ClassId[name.strip().upper()]
    except KeyError:
        known = ", ".join(CLASS_NAMES)
        raise ValueError(f"unknown class {name!r}; known classes: {known}") from None
