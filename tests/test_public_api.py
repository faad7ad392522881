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
