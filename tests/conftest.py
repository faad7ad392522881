"""Shared fixtures: synthetic scenes with known truth."""

import pytest

from vision_torsion.synthetic import Scene
from vision_torsion.synthetic.scene import DiskSpec


@pytest.fixture(scope="session")
def standard_scene():
    """The measurement core's standard scene, rotation centre off the pixel grid."""
    return Scene(disk=DiskSpec(center_x=700.37, center_y=500.61, background_level=200.0))


@pytest.fixture(scope="session")
def small_scene():
    """A small, fast scene (400x300 px, markers of radius 20 px, 200 px apart)."""
    return Scene().replace(
        image={"width": 400, "height": 300},
        disk={"center_x": 200.3, "center_y": 150.8},
        markers={"radius_px": 20.0, "distance_px": 100.0},
    )


SCENE_DIR = __import__("pathlib").Path(__file__).resolve().parents[1] / "vision_torsion" / "synthetic" / "scenes"


@pytest.fixture(scope="session")
def scene_file():
    """Path of a ready scene in the repository's synthetic/ folder, by name."""
    return lambda name: SCENE_DIR / f"{name}.toml"


@pytest.fixture
def cli_logging():
    """The command line configures the package's logger; give it back as it was for later tests."""
    import logging

    own = logging.getLogger("vision_torsion")
    level, handlers = own.level, list(own.handlers)
    yield
    own.setLevel(level)
    for h in list(own.handlers):
        if h not in handlers:
            own.removeHandler(h)
