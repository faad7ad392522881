"""Lazy public names for a package: imported from their submodule on first use.

So that ``import vision_torsion`` (or a subpackage) stays cheap and a command pays
only for what it uses (pandas, matplotlib and scipy.stats take ~0.3-0.6 s each).
"""

from __future__ import annotations

from importlib import import_module


def attach(package: str, table: dict[str, str]):
    """``__getattr__`` and ``__dir__`` for `package` serving `table` (name -> submodule).

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    table : dict
        Public name -> submodule (relative to `package`) that defines it.
    """
    import sys

    def __getattr__(name):
        module = table.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(table))

    return __getattr__, __dir__
