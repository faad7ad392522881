"""The import direction of ARCHITECTURE.md, enforced: nothing in vision_torsion/ imports
a module from a layer above its own, and packages beside each other at one level do
not import each other.

Imports are read from the source with ``ast`` (every ``import`` and ``from ... import``,
those inside functions included, and the submodules a package face's ``_LAZY`` table
names for :func:`vision_torsion.lazy.attach`), so a lazy import cannot hide a wrong
direction.
"""

import ast
from pathlib import Path

import pytest

import vision_torsion
import vision_torsion.cli

PACKAGE = Path(__file__).resolve().parents[1] / "vision_torsion"

# (level, group, module prefixes): a module may import modules of a lower level, and
# modules of its own level only within its own group. Keep in step with ARCHITECTURE.md.
LAYERS = [
    (0, "foundation", ["vision_torsion.__version__", "vision_torsion.lazy", "vision_torsion.errors",
                       "vision_torsion.fileio",
                       "vision_torsion.textfiles", "vision_torsion.resources", "vision_torsion.numerics",
                       "vision_torsion.batch", "vision_torsion.measurements", "vision_torsion.settings",
                       "vision_torsion.plotting", "vision_torsion.htmlpage", "vision_torsion.table_import",
                       "vision_torsion.progress", "vision_torsion.targets", "vision_torsion.validate"]),
    (1, "image", ["vision_torsion.images", "vision_torsion.pngrows", "vision_torsion.quality"]),
    (2, "markers", ["vision_torsion.ring", "vision_torsion.detect", "vision_torsion.edges",
                    "vision_torsion.pixelfit", "vision_torsion.circlefit", "vision_torsion.markers"]),
    (3, "pair", ["vision_torsion.pair"]),
    (4, "angle", ["vision_torsion.correction", "vision_torsion.angle", "vision_torsion.measure",
                  "vision_torsion.overlay", "vision_torsion.rigid", "vision_torsion.targetsheet"]),
    (5, "calibration", ["vision_torsion.calibration"]),
    (6, "session", ["vision_torsion.session"]),
    (7, "analysis", ["vision_torsion.analysis"]),
    (7, "stiffness", ["vision_torsion.stiffness"]),
    (8, "synthetic", ["vision_torsion.synthetic"]),
    (9, "report", ["vision_torsion.report"]),
    (10, "campaign", ["vision_torsion.campaign"]),
    (11, "cli", ["vision_torsion.cli", "vision_torsion.__main__"]),
    (12, "face", ["vision_torsion"]),
]


def layer_of(module: str):
    """(level, group) of a module: the layer with the longest matching prefix."""
    best = None
    for level, group, prefixes in LAYERS:
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > best[0]):
                best = (len(prefix), level, group)
    if best is None:
        raise KeyError(module)
    return best[1], best[2]


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path):
    """(line, imported vision_torsion module) of every import in a file."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in tree.body:  # a face's lazy table: {name: submodule} or (submodule, ...)
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets):
            entries = node.value.values if isinstance(node.value, ast.Dict) else getattr(node.value, "elts", [])
            for entry in entries:
                if isinstance(entry, ast.Constant) and isinstance(entry.value, str):
                    yield node.lineno, f"{package}.{entry.value}"
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "vision_torsion":
                    yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "vision_torsion":
                continue
            if node.module is None:  # from . import x: x may be a module
                for alias in node.names:
                    yield node.lineno, f"{target}.{alias.name}"
            else:
                yield node.lineno, target


def violations():
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        source = module_name(path)
        level, group = layer_of(source)
        for line, target in imports_of(path):
            t_level, t_group = layer_of(target)
            if t_level > level or (t_level == level and t_group != group):
                out.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {source} ({group}) imports {target} "
                           f"({t_group}, a layer above or beside it)")
    return out


def test_every_module_has_a_layer():
    unplaced = []
    for path in PACKAGE.rglob("*.py"):
        try:
            layer_of(module_name(path))
        except KeyError:
            unplaced.append(module_name(path))
    assert not unplaced, f"place these in LAYERS and ARCHITECTURE.md: {unplaced}"


def test_nothing_imports_a_layer_above_it():
    assert violations() == []


def test_the_check_sees_a_wrong_import(tmp_path, monkeypatch):
    """The test is not vacuous: an upward import (even inside a function) is found."""
    fake = tmp_path / "vision_torsion"
    (fake / "calibration").mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    (fake / "angle.py").write_text("def f():\n    from .session import load\n")
    (fake / "calibration" / "__init__.py").write_text("")
    (fake / "calibration" / "x.py").write_text("from ..stiffness import rig\nfrom ..angle import f\n")
    (fake / "images.py").write_text("from .lazy import attach\n_LAZY = {'Plan': 'session.plan'}\n")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", fake)
    found = violations()
    assert len(found) == 3
    assert "vision_torsion.angle (angle) imports vision_torsion.session" in found[0]
    assert "vision_torsion.calibration.x (calibration) imports vision_torsion.stiffness" in found[1]
    assert "vision_torsion.images (image) imports vision_torsion.session.plan" in found[2]


@pytest.mark.parametrize("module, expected", [
    ("vision_torsion.markers", (2, "markers")),
    ("vision_torsion.calibration.anchoring", (5, "calibration")),
    ("vision_torsion.correction", (4, "angle")),
    ("vision_torsion", (12, "face")),
    ("vision_torsion.__version__", (0, "foundation")),
])
def test_longest_prefix_decides_the_layer(module, expected):
    assert layer_of(module) == expected


def test_module_names_are_unique_except_a_commands_parser():
    """Two modules of one file name are allowed only as `cli/<command>.py` beside the
    module doing the command's work; everything else is named for what it holds."""
    root = Path(vision_torsion.__file__).parent
    by_name: dict[str, list[Path]] = {}
    for path in root.rglob("*.py"):
        if path.name != "__init__.py" and "__pycache__" not in path.parts:
            by_name.setdefault(path.name, []).append(path.relative_to(root))
    repeated = {name: paths for name, paths in by_name.items()
                if len([p for p in paths if p.parts[0] != "cli"]) > 1}
    assert not repeated, f"module file names repeated outside cli/: {repeated}"
    commands = set(vision_torsion.cli.COMMAND_MODULES)
    for name, paths in by_name.items():
        for path in paths:
            if path.parts[0] == "cli" and len(paths) > 1:
                assert path.stem in commands, f"cli/{path.name} repeats a module name but is no command's parser"
