"""The ``vision-torsion`` command: a thin layer over the Python API.

Each subcommand lives in its own module of this package and provides
``register(subparsers)``, which adds its parser and sets ``func`` to a function
taking the parsed arguments and returning the exit status. A subcommand module
imports only argparse-level things at the top; everything it needs to do its work
(numpy, pandas, matplotlib, scipy, ...) is imported inside its ``run`` function,
so ``vision-torsion --help`` and ``--version`` start in a fraction of a second.

Exit status
-----------
0
    everything succeeded;
1
    some item failed (an image, a check that did not pass);
2
    unusable input or output: a :class:`~vision_torsion.errors.VisionTorsionError`
    (bad file, bad manifest, an output folder that cannot be written, ...), or an
    operating-system error on a named file;
3
    an internal error (a bug): one line "internal error in COMMAND: ...; please
    report it", the traceback only with ``--debug``;
130
    interrupted (Ctrl-C).

Options every command has, before or after the subcommand's name: ``-q/--quiet``
(nothing on stdout, no progress bar; warnings and errors still go to stderr),
``-v/--verbose`` (the tool's own debug messages; other libraries stay quiet) and
``--debug`` (``-v``, and the traceback of an internal error). A new subcommand
gets them by calling :func:`add_common_options` on its parser.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import logging
import os
import sys

__all__ = ["main", "build_parser", "failure_line", "add_common_options", "progress_enabled",
           "EXIT_OK", "EXIT_FAILED", "EXIT_UNUSABLE", "EXIT_INTERNAL"]

EXIT_OK, EXIT_FAILED, EXIT_UNUSABLE, EXIT_INTERNAL = 0, 1, 2, 3

# Subcommand modules, in the order `--help` lists them.
_COMMAND_MODULES = [
    "measure",
    "synth",
    "plan",
    "target",
    "process",
    "bind",
    "watch",
    "report",
    "analyze",
    "demo",
    "check_accuracy",
    "calibrate",
    "stiffness",
]


def _add_common(parser: argparse.ArgumentParser, *, top: bool) -> None:
    # On subcommands the defaults are SUPPRESS, so "-v process" is not undone by
    # the subcommand's own (unset) -v.
    default = (lambda v: v) if top else (lambda v: argparse.SUPPRESS)
    g = parser.add_argument_group("output") if not top else parser
    g.add_argument("-q", "--quiet", action="store_true", default=default(False),
                   help="nothing on stdout and no progress bar; warnings and errors still go to stderr")
    g.add_argument("-v", "--verbose", action="store_true", default=default(False),
                   help="show the tool's own debug messages")
    g.add_argument("--debug", action="store_true", default=default(False),
                   help="like -v, and show the traceback of an internal error")


def add_common_options(parser: argparse.ArgumentParser) -> None:
    """Options every subcommand has: -q/--quiet, -v/--verbose, --debug (also accepted
    before the subcommand)."""
    _add_common(parser, top=False)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand registered."""
    import importlib

    parser = argparse.ArgumentParser(
        prog="vision-torsion",
        description="Torsional stiffness and hysteresis of precision gears from camera images.",
        epilog="Exit status: 0 success, 1 some item failed or a check did not pass, "
               "2 unusable input or output, 3 internal error.",
    )
    parser.add_argument("--version", action="version", version=_version())
    _add_common(parser, top=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in _COMMAND_MODULES:
        module = importlib.import_module(f".{name}", __name__)
        module.register(sub)
    return parser


def _version() -> str:
    from .. import __version__

    return f"vision-torsion {__version__}"


def progress_enabled(args) -> bool:
    """Progress bars show on a terminal unless --quiet was given."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


def failure_line(image: str, message: str, *, status: str = "failed") -> str:
    """One line for a failed item, naming the image once (most messages already do).

    A ``suspect`` item (measured, but not good data: :mod:`vision_torsion.quality`)
    is not called failed; the status decides, not the message's wording."""
    if status == "suspect":
        return f"{image}: {message}"
    return f"failed: {message}" if image in message else f"failed: {image}: {message}"


def _configure_logging(args) -> None:
    """The tool's own messages at the level asked for, on stderr; every other
    library's at WARNING (so -v does not bring matplotlib's font debugging)."""
    level = (logging.WARNING if args.quiet
             else logging.DEBUG if (args.verbose or args.debug) else logging.INFO)
    own = logging.getLogger("vision_torsion")
    for handler in list(own.handlers):
        if getattr(handler, "_vision_torsion_cli", False):
            own.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    handler._vision_torsion_cli = True
    own.addHandler(handler)
    own.setLevel(level)
    logging.captureWarnings(True)
    logging.getLogger("py.warnings").setLevel(logging.ERROR if args.quiet else logging.WARNING)


def _command_name(args) -> str:
    parts = [getattr(args, "command", None) or "vision-torsion"]
    for kind in ("kind",):
        if getattr(args, kind, None):
            parts.append(args.kind)
    return " ".join(parts)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def main(argv=None) -> int:
    """Run the command line; returns the exit status (see the module docstring).

    No Python traceback reaches the user: errors about input and output are one
    line naming the file and the reason (status 2); anything else is an internal
    error, one line and status 3 (the traceback with ``--debug``).
    """
    for stream in (sys.stdout, sys.stderr):  # a file name that is not UTF-8 must not crash a print
        with contextlib.suppress(AttributeError, ValueError):
            stream.reconfigure(errors="backslashreplace")
    parser = build_parser()
    args = parser.parse_args(argv)
    _configure_logging(args)
    command = _command_name(args)
    if argv is None:  # this process's own command line (the console script, python -m): it ends after
        with _ends_process(gc_off=getattr(args, "gc_off", False)):
            return _run(args, command)
    return _run(args, command)


@contextlib.contextmanager
def _ends_process(*, gc_off: bool):
    """The garbage collector of a process that ends with its command.

    At exit Python clears the modules and then collects: the cyclic garbage
    collector walks and frees, one by one, the ~130 000 objects numpy, pandas,
    scipy and matplotlib made at import, 0.3-0.5 s of CPU after ``vision-torsion
    analyze`` has written its last file (``benchmarks/bench_analyze.py``). Freezing
    them when the command is done leaves that memory to the operating system. The
    command's files are closed and renamed by then; atexit handlers (logging's flush)
    and the flush of stdout and stderr still run.

    A short batch command (``gc_off``, set by the subcommand's parser: ``analyze``)
    runs with the collector off: at the default thresholds it ran ~360 times on the
    demo table, walking those libraries' objects again and again (0.13-0.15 s of CPU)
    to find a few reference cycles (matplotlib figures) that go with the process;
    peak memory 153 -> 156 MB. Reference counting frees everything else.

    Only for the process's own command line, never for an in-process ``main([...])``,
    whose caller lives on.
    """
    if gc_off:
        gc.disable()
    try:
        yield
    finally:
        gc.freeze()


def _run(args, command: str) -> int:
    try:
        with contextlib.ExitStack() as stack:
            if args.quiet:
                devnull = stack.enter_context(open(os.devnull, "w", encoding="utf-8"))
                stack.enter_context(contextlib.redirect_stdout(devnull))
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `vision-torsion ... | head`
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w", encoding="utf-8")
        return EXIT_OK
    except Exception as exc:  # noqa: BLE001 - the one place every failure ends up
        return _report_error(exc, command=command, debug=args.debug)


def _report_error(exc: BaseException, *, command: str, debug: bool) -> int:
    from ..errors import VisionTorsionError

    if isinstance(exc, VisionTorsionError):
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_UNUSABLE
    if isinstance(exc, OSError) and exc.filename is not None:
        from ..fileio import os_reason

        name = os.fsdecode(exc.filename)
        print(f"error: {name}: {os_reason(exc)}", file=sys.stderr)
        return EXIT_UNUSABLE
    if isinstance(exc, MemoryError):
        print(f"error: {command}: out of memory", file=sys.stderr)
        return EXIT_UNUSABLE
    if debug:
        import traceback

        traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
    where = _origin(exc)
    print(f"internal error in {command}{where}: {type(exc).__name__}: {_one_line(exc)}; "
          "please report it (run again with --debug for the traceback)", file=sys.stderr)
    return EXIT_INTERNAL


def _origin(exc: BaseException) -> str:
    """" (module.function)" of the innermost frame of vision_torsion's own code."""
    tb, where = exc.__traceback__, ""
    while tb is not None:
        module = tb.tb_frame.f_globals.get("__name__", "")
        if module.startswith("vision_torsion"):
            where = f" ({module}.{tb.tb_frame.f_code.co_name})"
        tb = tb.tb_next
    return where


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
