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
``--debug`` (``-v``, and the traceback of an internal error). After the subcommand's
name, ``--force``: replace files in the way that vision-torsion cannot prove it wrote
(:mod:`vision_torsion.fileio`, the folder contract; without it such a file is refused
by name). A new subcommand gets them by calling :func:`add_common_options` on its parser.

Streams
-------
Everything printed goes through one place, :class:`Terminal`: control characters
and escape sequences (a camera file named to set the window title or clear the
screen) are shown escaped, never sent raw; a closed stdout or stderr (``2>&-``) or a
reader that went away (``| head``) silences that stream and never changes the exit
status.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import logging
import os
import re
import sys

__all__ = ["main", "build_parser", "COMMAND_MODULES", "failure_line", "add_common_options", "progress_enabled",
           "Terminal", "printable", "one_line", "EXIT_OK", "EXIT_FAILED", "EXIT_UNUSABLE", "EXIT_INTERNAL",
           "BLAS_THREAD_VARIABLES"]

EXIT_OK, EXIT_FAILED, EXIT_UNUSABLE, EXIT_INTERNAL = 0, 1, 2, 3

#: The subcommand modules of this package, in the order ``--help`` lists them; each
#: registers at least one command (:func:`build_parser`).
COMMAND_MODULES = (
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
    "campaign",
)


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
    if not top:
        try:
            g.add_argument("--force", action="store_true", default=False,
                           help="replace files in the output folder that vision-torsion cannot prove "
                                "it wrote (without it they are refused by name)")
        except argparse.ArgumentError:  # the command has its own --force (plan, synth, demo), meaning this too
            pass


def add_common_options(parser: argparse.ArgumentParser) -> None:
    """Options every subcommand has: -q/--quiet, -v/--verbose, --debug (also accepted
    before the subcommand) and --force (after it; kept when the command has its own)."""
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
    for name in COMMAND_MODULES:
        module = importlib.import_module(f".{name}", __name__)
        module.register(sub)
    return parser


def _version() -> str:
    from .. import __version__

    return f"vision-torsion {__version__}"


def progress_enabled(args) -> bool:
    """Progress shows unless --quiet was given: a bar on a terminal, a line every few
    seconds in a log or a pipe (:mod:`vision_torsion.progress`)."""
    return not getattr(args, "quiet", False)


def failure_line(image: str, message: str, *, status: str = "failed") -> str:
    """One line for a failed item, naming the image once (most messages already do).

    A ``suspect`` item (measured, but not good data: :mod:`vision_torsion.quality`)
    is not called failed, and an N-marker target's (``marker_missing``, ``ambiguous``,
    ``layout_mismatch``) is called by its status; the status decides, not the
    message's wording."""
    if status == "suspect":
        return one_line(f"{image}: {message}")
    return one_line(f"{status}: {message}" if image in message else f"{status}: {image}: {message}")


def one_line(text: str) -> str:
    """`text` with its line breaks shown escaped (``\\n``, ``\\r``): a file name holding one
    must not forge a line of the output (:class:`Terminal` escapes the other control
    characters, but keeps line breaks for the text that has several lines)."""
    return text.replace("\r", "\\r").replace("\n", "\\n")


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
    _fill_standard_fds()
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = Terminal(saved[0]), Terminal(saved[1])
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        _configure_logging(args)
        command = _command_name(args)
        if argv is None:  # this process's own command line (the console script, python -m): it ends after
            _one_blas_thread()
            with _ends_process(gc_off=getattr(args, "gc_off", False)):
                return _run(args, command)
        return _run(args, command)
    finally:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        sys.stdout, sys.stderr = saved


def _fill_standard_fds() -> None:
    """A closed descriptor 0, 1 or 2 (``2>&-``) opened on the null device, so the next
    file this process opens (a result) cannot land on it and receive what a library
    writes to "stderr"."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            with contextlib.suppress(OSError):
                new = os.open(os.devnull, os.O_RDWR)
                if new != fd:
                    os.dup2(new, fd)
                    os.close(new)


_UNPRINTABLE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]")
_NAMED = {"\r": "\\r", "\x1b": "\\x1b", "\x7f": "\\x7f"}


def printable(text: str) -> str:
    """`text` with control characters, escape sequences' introducer and bidirectional
    overrides shown as escapes (``\\x1b``, ``\\r``, ``\\u202e``); newline and tab kept.
    A leading carriage return is kept too: a progress bar redraws its line with it,
    and at the start of a write it can hide nothing written by the same write."""
    head = "\r" if text.startswith("\r") else ""
    body = text[len(head):]
    if _UNPRINTABLE.search(body) is None:
        return text
    return head + _UNPRINTABLE.sub(
        lambda m: _NAMED.get(m.group(), f"\\x{ord(m.group()):02x}" if ord(m.group()) < 0x100
                             else f"\\u{ord(m.group()):04x}"), body)


class Terminal:
    """stdout or stderr as the command line writes to it (the one place output goes).

    Every write is passed through :func:`printable`. A stream that is closed (None
    when Python started with it closed) or whose reader went away (a broken pipe)
    (or that cannot be written: a full disk) is silenced: its descriptor is pointed at the null device (so Python's own
    flush at exit cannot fail and change the exit status) and later writes are
    dropped. Other attributes are the wrapped stream's.
    """

    def __init__(self, stream):
        if isinstance(stream, Terminal):
            stream = stream._stream
        self._stream = stream
        self._broken = stream is None
        with contextlib.suppress(AttributeError, ValueError, OSError):
            stream.reconfigure(errors="backslashreplace")  # a non-UTF-8 file name must not crash a print

    def _silence(self) -> None:
        self._broken = True
        with contextlib.suppress(AttributeError, ValueError, OSError):
            fd = self._stream.fileno()
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, fd)
            os.close(devnull)

    def write(self, text: str) -> int:
        if not self._broken:
            try:
                self._stream.write(printable(text))
            except (OSError, ValueError):  # a broken pipe, a full disk; ValueError: a closed file
                self._silence()
        return len(text)

    def flush(self) -> None:
        if not self._broken:
            try:
                self._stream.flush()
            except (OSError, ValueError):
                self._silence()

    def isatty(self) -> bool:
        if self._broken:
            return False
        try:
            return bool(self._stream.isatty())
        except (AttributeError, OSError, ValueError):
            return False

    def __getattr__(self, name):
        if self._stream is None:
            raise AttributeError(name)
        return getattr(self._stream, name)


#: The environment variables by which a user sets the BLAS library's threads.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _one_blas_thread() -> None:
    """One BLAS thread for this command's process and its workers, unless the user
    set a count (:data:`BLAS_THREAD_VARIABLES`) or numpy is already imported.

    Every command measures with one BLAS thread (its matrices are 8 x a few
    thousand). Without this, OpenBLAS starts a thread per core when numpy is
    imported, and they spin on the other core while the command imports and
    starts, CPU that ``process``'s reading threads then wait for. Only for the
    process's own command line."""
    if "numpy" in sys.modules or any(name in os.environ for name in BLAS_THREAD_VARIABLES):
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"


@contextlib.contextmanager
def _ends_process(*, gc_off: bool):
    """The garbage collector of a process that ends with its command.

    On the way out the collector is frozen, so the objects the libraries made at
    import are left to the operating system instead of being walked and freed one
    by one; a short batch command (``gc_off``, set by its parser) also runs with the
    collector off. Files are closed and renamed before this; atexit handlers and the
    flush of stdout and stderr still run. Only for the process's own command line,
    never for an in-process ``main([...])``, whose caller lives on (the measured
    effect is in ``benchmarks/bench_analyze.py``'s results).
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
            from ..fileio import replacing_others

            stack.enter_context(replacing_others(getattr(args, "force", False)))
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
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
