"""Ready files shipped inside the package, named by their stem.

Scenes (``vision_torsion/synthetic/scenes/*.toml``: ``standard``, ``jpeg``,
``paper_session``, ...) and accuracy-check specs
(``vision_torsion/calibration/specs/*.toml``: ``rotary_stage``,
``synthetic_selfcheck``) are package data, so they exist in every install, editable
or not, and commands take their names (``--scene standard``, ``--spec
rotary_stage``) as well as paths to files of one's own.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["named_file", "available", "SCENES", "SPECS", "TARGETS", "CATALOGUES"]

#: (package, folder) of the ready scenes and of the ready accuracy-check specs.
SCENES = ("vision_torsion.synthetic", "scenes")
SPECS = ("vision_torsion.calibration", "specs")
#: (package, folder) of the ready target descriptions (``ring16``, ...).
TARGETS = ("vision_torsion", "targets")
#: (package, folder) of the ready gear catalogues (``[gear]`` and ``[spec]``: ``paper_demo``).
CATALOGUES = ("vision_torsion", "catalogues")


def available(kind: tuple[str, str]) -> list[str]:
    """Names of the ready files of `kind` (:data:`SCENES` or :data:`SPECS`)."""
    package, folder = kind
    root = resources.files(package) / folder
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def named_file(path, kind: tuple[str, str], *, error: type[Exception], what: str) -> Path:
    """`path` itself when it is a file (or looks like a path), else the ready file
    of that name.

    Parameters
    ----------
    path : str or os.PathLike
        A file, or the name of a ready file (no folder, no suffix).
    kind : tuple
        :data:`SCENES`, :data:`SPECS` or :data:`TARGETS`.
    error : exception class
        Raised for a name that is neither a file nor a ready file.
    what : str
        "scene", "spec" or "target", for the message.

    Raises
    ------
    error
        ``NAME: no such file, and no ready WHAT of that name (ready: a, b, ...)``.
    """
    p = Path(path)
    if p.exists() or p.suffix or len(p.parts) != 1:
        return p
    package, folder = kind
    ready = resources.files(package) / folder / f"{p.name}.toml"
    if ready.is_file():
        return Path(str(ready))
    raise error(f"{path}: no such file, and no ready {what} of that name "
                f"(ready: {', '.join(available(kind))})", reason="not_found")
