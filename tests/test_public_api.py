"""The public API: every name in __all__ resolves, and the import stays light."""

import importlib
import subprocess
import sys

import pytest

import vision_torsion
from vision_torsion.lazy import attach, module_all


def test_every_public_name_resolves():
    for name in vision_torsion.__all__:
        assert getattr(vision_torsion, name) is not None, name


def test_import_does_not_load_the_plotting_stack():
    code = "import sys, vision_torsion; print('matplotlib' in sys.modules, 'pandas' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_a_session_worker_imports_only_the_measuring_code():
    """A worker of `process` starts by importing session.worker (and the measuring
    code): pandas, scipy and matplotlib would cost each run about a second."""
    code = ("import sys, vision_torsion.session.worker, vision_torsion.pair; "
            "print(*(m in sys.modules for m in ('pandas', 'scipy', 'matplotlib')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False", "False"]


@pytest.mark.parametrize("face", ["analysis", "calibration", "session", "stiffness", "synthetic"])
def test_a_subpackage_face_is_its_modules_public_names(face):
    """A face serves exactly the __all__ of the modules its _LAZY table lists (read
    from their source), and each name is the object its module defines."""
    package = importlib.import_module(f"vision_torsion.{face}")
    expected = {}
    for module in package._LAZY:
        for name in importlib.import_module(f"vision_torsion.{face}.{module}").__all__:
            expected[name] = module
    assert sorted(package.__all__) == sorted(expected)
    for name, module in expected.items():
        assert getattr(package, name) is getattr(importlib.import_module(f"vision_torsion.{face}.{module}"), name)
    assert set(package.__all__) <= set(dir(package))


def test_importing_a_face_imports_none_of_its_modules():
    code = ("import sys, vision_torsion.stiffness, vision_torsion.analysis; "
            "print(*(m in sys.modules for m in ('matplotlib', 'scipy', 'vision_torsion.stiffness.section')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False", "False"]


def _fake_face(tmp_path, monkeypatch, name: str, modules: dict):
    package = tmp_path / name
    package.mkdir()
    (package / "__init__.py").write_text("")
    for module, text in modules.items():
        (package / f"{module}.py").write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))
    return importlib.import_module(name)


def test_a_name_public_in_two_modules_of_a_face_is_refused(tmp_path, monkeypatch):
    _fake_face(tmp_path, monkeypatch, "fakeface", {"a": "__all__ = ['fit']\n", "b": "__all__ = ('fit',)\n"})
    with pytest.raises(ImportError, match=r"fakeface: 'fit' is public in both \.a and \.b"):
        attach("fakeface", ("a", "b"))


def test_a_face_module_needs_a_literal_all(tmp_path, monkeypatch):
    _fake_face(tmp_path, monkeypatch, "fakeface2", {"c": "NAMES = ['x']\n__all__ = NAMES\n"})
    with pytest.raises(ImportError, match="fakeface2.c must define __all__ as a literal list of names"):
        module_all("fakeface2.c")
    (tmp_path / "fakeface2" / "d.py").write_text("__all__ = [\n    'x',  # the first\n    'y',\n]\n")
    assert module_all("fakeface2.d") == ["x", "y"]
