"""Command-line options shared by the commands that measure images."""

from __future__ import annotations

from ..settings import FIT_METHODS, POLARITIES, MeasureSettings

__all__ = ["add_marker_options", "add_jobs_option", "settings_from_args"]


def add_marker_options(parser) -> None:
    """--polarity, --radius-range, --fit and --correction."""
    g = parser.add_argument_group("markers")
    g.add_argument("--polarity", choices=POLARITIES, default="dark", help="dark markers on a bright disk (default) or bright on dark")
    g.add_argument(
        "--radius-range", nargs=2, type=float, metavar=("MIN", "MAX"), help="marker radius range in pixels"
    )
    g.add_argument("--fit", choices=FIT_METHODS, default="pixels",
                   help="marker fit: pixels (default: the disc model fitted to the pixels), or a fit to "
                        "edge points: geometric, algebraic (the paper's), ellipse")
    g.add_argument(
        "--correction", metavar="FILE", help="plane/lens correction (TOML or JSON from `calibrate`) applied to the marker centres"
    )


def add_jobs_option(parser) -> None:
    """-j/--jobs: how many images are read and decoded at once."""
    parser.add_argument("-j", "--jobs", type=int, metavar="N",
                        help="images read and decoded at once (default: all cores); up to 3 "
                             "as threads of this process, more as worker processes")


def settings_from_args(args) -> MeasureSettings:
    """MeasureSettings from parsed marker options."""
    return MeasureSettings(
        polarity=args.polarity,
        radius_range=tuple(args.radius_range) if args.radius_range else None,
        fit=args.fit,
        correction=getattr(args, "correction", None),
    )
