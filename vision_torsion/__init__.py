"""vision-torsion: torsional stiffness and hysteresis of precision gears from camera images."""

__version__ = "0.1.0"

from .errors import *  # noqa: F401,F403
from .errors import __all__ as _errors_all
from .images import GreyImage, load_image
from .settings import MeasureSettings

__all__ = [*_errors_all, "GreyImage", "load_image", "MeasureSettings"]
