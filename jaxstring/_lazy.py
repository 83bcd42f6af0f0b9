"""Modules imported where they are first used.

diffrax and optimistix (with lineax) take longer to import than a small solve
takes to run (docs/performance.md, "A warm process imports only what it runs"),
and a process that runs saved programs (`jaxstring._programs`) neither traces
nor builds a solver: the modules it passes through name them as `diffrax` and
`optimistix` below, imported at the first attribute read. Modules that subclass
their classes import them as usual and are themselves imported where used.
"""

import importlib
import sys


class Module:
    """A module imported at the first read of one of its attributes."""

    def __init__(self, name: str):
        self.__dict__["_name"] = name

    def __getattr__(self, attr):
        return getattr(importlib.import_module(self._name), attr)

    def __repr__(self) -> str:
        return f"<module {self._name!r}, imported at first use>"


diffrax = Module("diffrax")
optimistix = Module("optimistix")


def is_instance(x, module: str, cls: str) -> bool:
    """`isinstance(x, module.cls)` without importing `module`: no object is an
    instance of a class of a module not yet imported."""
    m = sys.modules.get(module)
    return m is not None and isinstance(x, getattr(m, cls))
