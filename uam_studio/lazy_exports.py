"""A package's names imported only when first used (a module ``__getattr__``, PEP 562), so that importing
the package stays light: ``__getattr__ = lazy_getattr(__name__, {"name": "uam_studio.module", ...})``; a
value ``"uam_studio.module:attr"`` exports that module's ``attr`` under the key's name."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping

__all__ = ["lazy_getattr"]


def lazy_getattr(package: str, names: Mapping[str, str]) -> Callable[[str], object]:
    """A module ``__getattr__`` for ``package``: each name of ``names`` is read from its module (the
    mapping's value: a full dotted path, optionally ``:attr`` for another name there) when first asked
    for; any other name raises AttributeError."""

    def __getattr__(name: str) -> object:
        if name in names:
            module, _, attr = names[name].partition(":")
            return getattr(importlib.import_module(module), attr or name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
