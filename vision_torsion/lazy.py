"""Lazy package faces: a package's public names, imported from their module on first use.

Every package face (the root and each subpackage ``__init__``) is built the same way:
a module-level ``_LAZY`` table given to :func:`attach`. So ``import vision_torsion``
(or a subpackage) stays cheap and a command pays only for what it uses (pandas,
matplotlib and scipy.stats take ~0.3-0.6 s each). ``tests/test_architecture.py``
reads the ``_LAZY`` tables as imports, so a lazy name cannot hide a wrong direction.
"""

from __future__ import annotations

import sys
from importlib import import_module

__all__ = ["attach", "module_all"]

#: The ``__all__ = [...]`` (or ``(...)``) assignment at the start of a line.
_ALL = r"^__all__\s*=\s*([\[(].*?[\])])"


def module_all(module: str) -> list[str]:
    """The public names (``__all__``) of the module named `module`, without importing it.

    Read from the module's source (the literal list or tuple assigned to ``__all__``),
    or from the module itself when it is already imported or has no source (an
    install without ``.py`` files).

    Raises
    ------
    ImportError
        `module` does not exist, or defines no ``__all__`` of string literals.
    """
    loaded = sys.modules.get(module)
    if loaded is not None and hasattr(loaded, "__all__"):
        return list(loaded.__all__)
    from importlib.util import find_spec  # here: the root face never needs it

    spec = find_spec(module)
    if spec is None:
        raise ImportError(f"no module named {module!r}", name=module)
    # a loader that cannot give source (pytest's assertion rewriter, a zip without
    # .py files): import the module instead
    get_source = getattr(spec.loader, "get_source", None)
    source = get_source(module) if get_source is not None else None
    if source is None:
        return list(import_module(module).__all__)
    import ast  # here: a face used only by its imported names never needs them
    import re

    found = re.search(_ALL, source, re.MULTILINE | re.DOTALL)
    try:
        names = ast.literal_eval(found.group(1)) if found else None
    except (ValueError, SyntaxError):
        names = None
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise ImportError(f"{module} must define __all__ as a literal list of names (its package face reads it)",
                          name=module)
    return list(names)


def attach(package: str, table):
    """``__getattr__`` and ``__dir__`` for the face of `package`, and its ``__all__``.

    Parameters
    ----------
    package : str
        The package's ``__name__`` (called from its ``__init__``).
    table : dict or sequence of str
        Either public name -> submodule that defines it (a curated face: the root),
        or submodules (relative to `package`) whose ``__all__`` together are the
        face (:func:`module_all`, read from their source: a subpackage).

    Returns
    -------
    tuple
        ``(__getattr__, __dir__)`` for the package module (PEP 562). The package's
        ``__all__`` is set to the face's names.

    Raises
    ------
    ImportError
        Two of the submodules declare the same public name.

    Notes
    -----
    A public name that is also the name of one of the face's submodules (the
    function ``render`` of ``synthetic/render.py``) is imported at once: importing
    the submodule binds its name on the package to the module, and a module
    attribute once set is never asked of ``__getattr__`` again.
    """
    if isinstance(table, dict):
        names = dict(table)
    else:
        names = {}
        for module in table:
            for name in module_all(f"{package}.{module}"):
                if names.setdefault(name, module) != module:
                    raise ImportError(f"{package}: {name!r} is public in both .{names[name]} and .{module}",
                                      name=package)
    face = sys.modules[package]
    face.__all__ = list(names)
    for name, module in names.items():
        if name == module:
            setattr(face, name, getattr(import_module(f".{module}", package), name))

    def __getattr__(name):
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(f".{module}", package), name)
        setattr(face, name, value)
        return value

    def __dir__():
        return sorted(set(vars(face)) | set(names))

    return __getattr__, __dir__
