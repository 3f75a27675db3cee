"""Ground floor of hollowtree: the class vocabulary and the error types.

The run store, readers and ingest (issue 3) are not built yet; this package holds only
what every other floor imports.
"""

from hollowtree.tiling.classes import (
    CLASS_NAMES,
    ELEMENT_CLASSES,
    NUM_CLASSES,
    PLANAR_CLASSES,
    ClassId,
    class_id,
)
from hollowtree.tiling.errors import ConfigError, InputFileError, OutputExistsError, PipelineError

__all__ = [
    "CLASS_NAMES",
    "ELEMENT_CLASSES",
    "NUM_CLASSES",
    "PLANAR_CLASSES",
    "ClassId",
    "class_id",
    "ConfigError",
    "InputFileError",
    "OutputExistsError",
    "PipelineError",
]
