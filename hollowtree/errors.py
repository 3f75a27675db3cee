"""The one error hierarchy of hollowtree.

Every expected failure of user input raises a subclass of :class:`PipelineError`, which
also inherits the builtin it refines, so ``except ValueError`` keeps working. The CLI
turns any :class:`PipelineError` into a one-line message and exit code 2.
"""

from __future__ import annotations

__all__ = [
    "PipelineError",
    "ConfigError",
    "InputFileError",
    "CorruptInputError",
    "UnsupportedInputError",
    "OutputExistsError",
]


class PipelineError(Exception):
    """Base class of every error hollowtree raises on purpose."""


class ConfigError(PipelineError, ValueError):
    """A parameter or configuration value is invalid."""


class InputFileError(PipelineError, FileNotFoundError):
    """An input file or folder is missing or unreadable."""


class CorruptInputError(PipelineError, ValueError):
    """An input file exists but is empty, truncated or not the format its name says."""


class UnsupportedInputError(PipelineError, ValueError):
    """An input file's format is unknown, or its optional reader is not installed."""


class OutputExistsError(PipelineError, FileExistsError):
    """An output would overwrite an existing file and overwriting was not asked for."""
