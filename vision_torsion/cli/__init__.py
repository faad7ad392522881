"""The ``vision-torsion`` command: a thin layer over the Python API.

Each subcommand lives in its own module of this package and provides
``register(subparsers)``, which adds its parser and sets ``func`` to a function
taking the parsed arguments and returning the exit status. Exit status: 0 when
everything succeeded, 1 when some item failed (or a check did not pass), 2 for
unusable input.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from ..errors import VisionTorsionError

__all__ = ["main", "build_parser", "failure_line"]

# Subcommand modules, in the order `--help` lists them.
_COMMAND_MODULES = [
    "measure",
    "synth",
    "plan",
    "process",
    "report",
    "demo",
    "check_accuracy",
    "calibrate",
    "stiffness",
]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="vision-torsion",
        description="Torsional stiffness and hysteresis of precision gears from camera images.",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in _COMMAND_MODULES:
        module = importlib.import_module(f".{name}", __name__)
        module.register(sub)
    return parser


def _version() -> str:
    from .. import __version__

    return f"vision-torsion {__version__}"


def add_common_options(parser: argparse.ArgumentParser) -> None:
    """Options every subcommand has: --quiet and --verbose."""
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="no progress bar, only warnings and errors"
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log details")


def progress_enabled(args) -> bool:
    """Progress bars show on a terminal unless --quiet was given."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


def failure_line(image: str, message: str) -> str:
    """One line for a failed item, naming the image once (most messages already do)."""
    return f"failed: {message}" if image in message else f"failed: {image}: {message}"


def main(argv=None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING if args.quiet else (logging.DEBUG if args.verbose else logging.INFO)
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except VisionTorsionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
