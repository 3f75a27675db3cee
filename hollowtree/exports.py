"""A package's public names, imported on first use (PEP 562).

A package lists each public name once, beside the module that defines it; importing the
package (or a light module of it, such as ``tree.build_params``) loads nothing else::

    __all__, __getattr__ = lazy_exports(__name__, {"build": "NodeTable build_tree"})
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, table: Mapping[str, str]) -> tuple[list[str], Callable[[str], Any]]:
    """The ``__all__`` and the module ``__getattr__`` of ``package``, whose public names
    are ``table``: ``{"submodule": "name name ..."}``. A submodule's own name imports it.

    Examples
    --------
    >>> names, get = lazy_exports("hollowtree", {"errors": "ConfigError InputFileError"})
    >>> names, get("ConfigError").__name__, get("errors").__name__
    (['ConfigError', 'InputFileError'], 'ConfigError', 'hollowtree.errors')
    """
    where = {name: module for module, names in table.items() for name in names.split()}

    def __getattr__(name: str) -> Any:
        if name in where:
            return getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        if not name.startswith("__") and importlib.util.find_spec(f"{package}.{name}") is not None:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return sorted(where), __getattr__
