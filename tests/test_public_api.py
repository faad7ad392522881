"""The public API: every name in __all__ resolves, and the import stays light."""

import subprocess
import sys

import vision_torsion


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


def test_subpackages_resolve_their_lazy_names():
    import vision_torsion.calibration as calibration
    import vision_torsion.session as session

    for package in (calibration, session):
        for name in package.__all__:
            assert getattr(package, name) is not None, name
        assert set(package.__all__) <= set(dir(package))
