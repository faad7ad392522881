"""Streams (issue 30): a closed stdout or stderr (``>&-``, ``2>&-``) or a reader that
went away (``process s | head``) never crashes a command and never changes its exit
status; file names with control characters or escape sequences are shown escaped.

The commands run as their own processes (``python -m vision_torsion`` under bash, as
a user types them), on folders made here at run time (no binary fixtures); each case
also checks that inputs are unchanged (hashed before and after).
"""

from __future__ import annotations

import io
import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import draw_target, make_session, tree_digest, write_image

from vision_torsion.cli import Terminal, main, printable

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONWARNINGS": "error"}
ESCAPE_NAME = "bad\x1b]0;pwned\x07\x1b[2J.png"  # sets the window title, clears the screen


def shell(command: str, *args, tail: str = "") -> subprocess.CompletedProcess:
    """``python -m vision_torsion COMMAND ARGS TAIL`` under bash (TAIL: redirections)."""
    line = " ".join([shlex.quote(sys.executable), "-m", "vision_torsion", command,
                     *(shlex.quote(str(a)) for a in args)])
    return subprocess.run(["bash", "-c", f"{line} {tail}"], cwd=ROOT, env=ENV, capture_output=True,
                          timeout=300)


@pytest.fixture
def session(tmp_path):
    """A small session whose second image is not an image: ``process`` exits 1."""
    folder = tmp_path / "session"
    plan, _ = make_session(folder, orientations=(0,))
    (folder / plan.rows[1]["image"]).write_bytes(b"not an image at all")
    return folder


@pytest.fixture
def photos(tmp_path):
    """Three photographs of the target, and one broken file with an escape sequence in its name."""
    folder = tmp_path / "photos"
    folder.mkdir()
    for k, angle in enumerate((0.0, 2.0, 4.5)):
        write_image(folder / f"img_{k}.png", draw_target(angle))
    (folder / ESCAPE_NAME).write_bytes(b"\x89PNG broken")
    return folder


@pytest.mark.parametrize("tail", ["2>&-", ">&-", ">&- 2>&-"], ids=["stderr", "stdout", "both"])
def test_a_failed_image_keeps_status_1_with_a_closed_stream(session, tmp_path, tail):
    before = tree_digest(session)
    res = shell("process", session, "-o", tmp_path / "out", "--jobs", "1", tail=tail)
    assert res.returncode == 1, res.stderr
    assert b"Traceback" not in res.stdout + res.stderr and b"internal error" not in res.stderr
    assert (tmp_path / "out" / "measurements.csv").is_file()
    assert tree_digest(session) == before


def test_a_failed_image_keeps_status_1_when_the_reader_goes_away(session, tmp_path):
    """``process s | head``: the reader has gone before the summary is printed."""
    cmd = [sys.executable, "-m", "vision_torsion", "process", str(session), "-o", str(tmp_path / "out"),
           "--jobs", "1"]
    with subprocess.Popen(cmd, cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        proc.stdout.close()  # nobody reads stdout: every write to it is a broken pipe
        err = proc.stderr.read()
        assert proc.wait(timeout=300) == 1, err
    assert b"Traceback" not in err and b"Exception ignored" not in err
    assert b"failed:" in err  # stderr still works


@pytest.mark.parametrize("command", ["measure", "check-accuracy", "report", "synth"])
def test_commands_run_with_stderr_closed(tmp_path, photos, command):
    if command == "measure":
        args = [photos, "--reference", photos / "img_0.png", "-o", tmp_path / "out"]
        expected = 1  # the broken file
    elif command == "check-accuracy":
        assert main(["-q", "synth", "accuracy", str(tmp_path / "acc"), "--scene", "standard",
                     "--angles", "0", "5", "-30"]) == 0
        args, expected = [tmp_path / "acc", "-o", tmp_path / "out", "--tolerance", "1"], 0
    elif command == "report":
        make_session(tmp_path / "session", orientations=(0,))
        args, expected = [tmp_path / "session", "-o", tmp_path / "out", "--jobs", "1"], 0
    else:
        args, expected = ["accuracy", tmp_path / "out", "--scene", "standard", "--angles", "0", "5"], 0
    inputs = tree_digest(tmp_path, exclude=["out"])
    res = shell(command, *args, tail="2>&-")
    assert res.returncode == expected, res.stdout
    assert b"wrote" in res.stdout or b"report:" in res.stdout
    assert tree_digest(tmp_path, exclude=["out"]) == inputs


def test_version_with_stdout_closed_is_status_0():
    assert shell("--version", tail=">&-").returncode == 0


# -- control characters ----------------------------------------------------------------


def test_an_escape_sequence_in_a_file_name_is_shown_escaped(photos, tmp_path):
    res = shell("measure", photos, "--reference", photos / "img_0.png", "-o", tmp_path / "out")
    assert res.returncode == 1
    shown = res.stderr.decode()
    assert "bad\\x1b]0;pwned\\x07\\x1b[2J.png" in shown  # named, escaped
    assert "\x1b" not in shown and "\x07" not in shown
    assert "\x1b" not in res.stdout.decode()


@pytest.mark.parametrize(("text", "shown"), [
    ("plain name.png: ok\n", "plain name.png: ok\n"),
    ("tab\tand newline\n", "tab\tand newline\n"),
    ("a\x1b[2Jb", "a\\x1b[2Jb"),
    ("bell\x07", "bell\\x07"),
    ("back\x08space", "back\\x08space"),
    ("cr\rhides", "cr\\rhides"),
    ("\r 40%|####  |", "\r 40%|####  |"),  # a progress bar redraws its line
    ("c1\x9bcontrol", "c1\\x9bcontrol"),
    ("rtl\u202efdp.exe", "rtl\\u202efdp.exe"),
    ("del\x7f", "del\\x7f"),
    ("ünïcödé 30° ±0.1", "ünïcödé 30° ±0.1"),
])
def test_printable(text, shown):
    assert printable(text) == shown


class _Gone(io.StringIO):
    """A stream whose reader has gone."""

    def write(self, text):
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        raise BrokenPipeError(32, "Broken pipe")


def test_terminal_silences_a_broken_stream_and_a_missing_one():
    gone = Terminal(_Gone())
    assert gone.write("summary\n") == len("summary\n")
    gone.flush()
    assert gone.write("more\n") == len("more\n") and not gone.isatty()
    missing = Terminal(None)  # Python started with the stream closed
    assert missing.write("x") == 1 and not missing.isatty()
    missing.flush()
    shown = io.StringIO()
    Terminal(shown).write("IMG\x1b]0;x\x07.png\n")
    assert shown.getvalue() == "IMG\\x1b]0;x\\x07.png\n"
