"""Lazy exports of a package: a name re-exported from a submodule that is imported only when
the name is first read (PEP 562), so importing the package stays cheap.

In a package's ``__init__.py``::

    __getattr__, __dir__ = lazy_exports(__name__, {"run_tardieu": "tardieu"})
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(
    package: str, homes: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` of *package* for the names of *homes*
    (name -> submodule, relative to *package*, that defines it)."""
    table = dict(homes)

    def __getattr__(name: str) -> Any:
        if name in table:
            return getattr(importlib.import_module(f"{package}.{table[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        module = importlib.import_module(package)
        return sorted({*vars(module), *table})

    return __getattr__, __dir__
