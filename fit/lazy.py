"""Attributes of a package imported on first use (PEP 562 ``__getattr__``), so that importing
the package stays cheap: ``fit`` (SciPy-heavy fitters) and ``fit.batch`` (Dask)."""
from __future__ import annotations

from importlib import import_module


def lazy_attributes(package: str, table: dict, namespace: dict):
    """A module ``__getattr__`` for ``package``: ``table`` maps an attribute name to
    ``(module, attribute)``; the value is imported on first access and stored in ``namespace``
    (the package's ``globals()``), so later accesses do not come back here."""

    def __getattr__(name):
        if name in table:
            module, attr = table[name]
            value = getattr(import_module(module), attr)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
