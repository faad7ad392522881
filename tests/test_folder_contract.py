"""The folder contract (issue 30): a command creates, replaces or deletes only files it
can prove it wrote; anything else in its way is refused by name, with ``--force``
explained, and nothing outside its output folder is touched.

Every case runs the command line in this process (``cli.main``) on files made here at
run time (no binary fixtures) and checks, for each command:

- the exit status (2: unusable output, refused before or without replacing anything);
- the message names the file in the way and says why (not written by vision-torsion)
  and how to go on (``--force``);
- inputs and the file in the way are unchanged (hashed before and after);
- nothing outside the output folder is created, changed or removed (the whole tree
  around it hashed, with a foreign ``.cache/`` holding someone else's ``.jsonl`` and a
  foreign ``report.html`` beside it).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from helpers import draw_target, make_session, run_cli, tree_digest, write_image

from vision_torsion import fileio
from vision_torsion.cli import main
from vision_torsion.errors import OutputError
from vision_torsion.session.cache import CACHE_DIRNAME, CacheLog, merge_cache, read_cache, read_logs

FOREIGN = b"someone else's file: not to be lost\n"
ENTRY = '{"status": "ok", "value": 1}'


run = run_cli


def refused_by_name(err: str, path: Path) -> None:
    """The one-line message of a refusal: the file, why, and --force."""
    assert f"error: {path}: not replaced: vision-torsion did not write this file" in err, err
    assert "--force" in err


@pytest.fixture
def home(tmp_path):
    """A user's folder: a session, its results (for analyze and stiffness), a folder of
    photos, someone else's ``.cache/`` and ``report.html``, and a note."""
    root = tmp_path / "home"
    make_session(root / "session", orientations=(0,))
    assert main(["-q", "process", str(root / "session"), "-o", str(root / "table"), "--jobs", "1"]) == 0
    photos = root / "photos"
    photos.mkdir()
    for k, angle in enumerate((0.0, 3.0, 7.5)):
        write_image(photos / f"img_{k}.png", draw_target(angle))
    (root / ".cache").mkdir()
    (root / ".cache" / "someone.jsonl").write_bytes(FOREIGN)
    (root / "report.html").write_bytes(FOREIGN)
    (root / "notes.txt").write_bytes(FOREIGN)
    return root


def _argv(home: Path, out: Path, command: str) -> list:
    s, table, photos = home / "session", home / "table" / "measurements.csv", home / "photos"
    if command == "check-accuracy" and not (home / "acc").exists():
        assert main(["-q", "synth", "accuracy", str(home / "acc"), "--scene", "standard",
                     "--angles", "0", "5", "-30"]) == 0
    return {
        "process": ["process", s, "-o", out, "--jobs", "1"],
        "report": ["report", s, "-o", out, "--jobs", "1"],
        "measure": ["measure", photos, "--reference", photos / "img_0.png", "-o", out],
        "analyze": ["analyze", table, "-o", out],
        "stiffness": ["stiffness", table, "-o", out],
        "calibrate": ["calibrate", "plane", photos, "--reference", photos / "img_0.png", "-o", out],
        "plan": ["plan", out, "--steps", "2", "--step-mass", "0.02", "--arm-radius", "0.05", "--no-pdf"],
        "check-accuracy": ["check-accuracy", home / "acc", "-o", out, "--tolerance", "1"],
        "watch": ["watch", s, "-o", out, "--poll", "0.05", "--settle", "0", "--no-report"],
    }[command]


# (command, the result file another program left in the output folder)
IN_THE_WAY = [
    ("process", "measurements.csv"),
    ("report", "report.html"),
    ("report", "summary.json"),
    ("report", "measurements.csv"),
    ("measure", "angles.csv"),
    ("analyze", "report.html"),
    ("analyze", "summary.json"),
    ("stiffness", "stiffness_curve.csv"),
    ("calibrate", "plane_correction.toml"),
    ("plan", "capture_sheet.html"),
    ("watch", "live.html"),
    ("watch", "live-stamp.js"),
    ("check-accuracy", "accuracy.json"),
    # found only when written: replaced as a set with the rest, so nothing is
    ("report", "figures/loops_overlay.svg"),
    ("analyze", "figures/fit_residuals.svg"),
    ("stiffness", "step_stiffness.png"),
]


@pytest.mark.parametrize(("command", "name"), IN_THE_WAY, ids=[f"{c}-{n}" for c, n in IN_THE_WAY])
def test_a_result_file_the_tool_did_not_write_is_refused_by_name(capsys, home, command, name):
    out = home / "out"
    (out / name).parent.mkdir(parents=True)
    (out / name).write_bytes(FOREIGN)
    argv = _argv(home, out, command)
    before = tree_digest(home, exclude=["out"])
    code, _, err = run(capsys, *argv)
    assert code == 2
    refused_by_name(err, out / name)
    assert (out / name).read_bytes() == FOREIGN
    assert tree_digest(home, exclude=["out"]) == before  # inputs and everything around unchanged


@pytest.mark.parametrize("command", ["process", "report", "measure", "analyze", "stiffness", "check-accuracy"])
def test_a_command_replaces_its_own_files_without_force(capsys, home, command):
    out = home / "out"
    argv = _argv(home, out, command)
    assert run(capsys, *argv)[0] == 0
    before = tree_digest(home, exclude=["out"])
    assert run(capsys, *argv)[0] == 0  # the README's promise: own result files need no --force
    assert tree_digest(home, exclude=["out"]) == before


def test_force_replaces_a_file_the_tool_did_not_write(capsys, home):
    out = home / "out"
    out.mkdir()
    (out / "measurements.csv").write_bytes(FOREIGN)
    before = tree_digest(home, exclude=["out"])
    code, _, err = run(capsys, *_argv(home, out, "process"), "--force")
    assert code == 0, err
    assert (out / "measurements.csv").read_bytes().startswith(b"image,")
    assert fileio.is_ours(out / "measurements.csv")
    assert tree_digest(home, exclude=["out"]) == before


def test_an_own_file_changed_by_hand_is_refused(capsys, home):
    out = home / "out"
    assert run(capsys, *_argv(home, out, "process"))[0] == 0
    with open(out / "measurements.csv", "a", encoding="utf-8") as fh:
        fh.write("my notes\n")
    edited = (out / "measurements.csv").read_bytes()
    code, _, err = run(capsys, *_argv(home, out, "process"))
    assert code == 2
    assert "(or it was changed since)" in err
    refused_by_name(err, out / "measurements.csv")
    assert (out / "measurements.csv").read_bytes() == edited


def test_bind_refuses_a_binding_it_did_not_write_before_measuring(capsys, home):
    session = home / "session"
    assert run(capsys, "bind", session, session / "images")[0] in (0, 1)  # 1: steps to look at
    assert fileio.is_ours(session / "binding.json")
    edited = (session / "binding.json").read_bytes() + b" \n"  # still valid, but edited by hand
    (session / "binding.json").write_bytes(edited)
    shutil.rmtree(home / "session" / "results")
    before = tree_digest(home)
    code, _, err = run(capsys, "bind", session, session / "images")
    assert code == 2
    refused_by_name(err, session / "binding.json")
    assert tree_digest(home) == before  # not even the cache: refused before any measuring


def test_synth_refuses_a_non_empty_folder(capsys, home):
    before = tree_digest(home)
    for kind, scene in (("accuracy", "standard"), ("session", "paper_session")):
        code, _, err = run(capsys, "synth", kind, home / "session", "--scene", scene)
        assert code == 2
        assert f"{home / 'session'}: folder exists and is not empty; use --force" in err
    assert tree_digest(home) == before


# -- demo ------------------------------------------------------------------------------


def test_demo_refuses_a_folder_holding_the_user_s_own_session(capsys, home):
    before = tree_digest(home)
    code, _, err = run(capsys, "demo", home)  # home/session is the user's session
    assert code == 2
    assert f"error: {home}: folder exists and is not empty, and vision-torsion did not write a demo" in err
    assert "--force" in err
    assert tree_digest(home) == before


def test_demo_refuses_any_non_empty_folder_it_did_not_make(capsys, tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "thesis.tex").write_bytes(FOREIGN)
    before = tree_digest(tmp_path)
    assert run(capsys, "demo", folder)[0] == 2
    assert tree_digest(tmp_path) == before


# -- the cache -------------------------------------------------------------------------


def test_output_folder_home_leaves_the_user_s_cache_alone(capsys, home):
    """``-o ~``: the output folder holds someone else's ``.cache/`` and ``report.html``."""
    out = home  # the whole user's folder is the output folder
    outside = tree_digest(home, exclude=["table"])  # everything there except what process writes
    code, _, err = run(capsys, "process", home / "session", "-o", out, "--jobs", "1")
    assert code == 0, err
    after = tree_digest(home, exclude=["table"])
    new = sorted(set(after) - set(outside))
    assert all(name in after and after[name] == digest for name, digest in outside.items())
    assert new == sorted(["measurements.csv", fileio.RECORD_NAME, CACHE_DIRNAME,
                          *(f"{CACHE_DIRNAME}/{p.name}" for p in (home / CACHE_DIRNAME).iterdir())])
    # and again: the cache is merged, the user's .cache still untouched
    assert run(capsys, "process", home / "session", "-o", out, "--jobs", "1")[0] == 0
    assert (home / ".cache" / "someone.jsonl").read_bytes() == FOREIGN


def test_the_cache_reads_merges_and_removes_only_its_own_logs(tmp_path):
    folder = tmp_path / CACHE_DIRNAME
    folder.mkdir()
    strangers = {  # a name of the cache's pattern but not recorded, and another name
        "run-feedfeedfeed-1.jsonl": FOREIGN, "notes.jsonl": FOREIGN}
    for name, data in strangers.items():
        (folder / name).write_bytes(data)
    log = CacheLog(folder, CacheLog.new_run())
    log.append("a" * 64, ENTRY)
    log.close()
    entries, files = read_cache(folder)
    assert files == log.files() and list(entries) == ["a" * 64]
    merge_cache(folder, read_logs(files), files + [folder / name for name in strangers])
    assert {name: (folder / name).read_bytes() for name in strangers} == strangers
    assert not log.files()  # its own log merged and removed


def test_the_cache_never_writes_over_someone_else_s_merged_log(tmp_path):
    folder = tmp_path / CACHE_DIRNAME
    folder.mkdir()
    (folder / "merged.jsonl").write_bytes(FOREIGN)
    with fileio.replacing_others():  # not even with --force
        with pytest.raises(OutputError, match=r"merged\.jsonl: not replaced: vision-torsion did not write") as err:
            merge_cache(folder, {}, [])
    assert err.value.reason == "not_ours"
    assert (folder / "merged.jsonl").read_bytes() == FOREIGN


def test_a_cache_log_is_never_opened_over_an_existing_file(tmp_path):
    folder = tmp_path / CACHE_DIRNAME
    log = CacheLog(folder, "r1")
    log.append("a" * 64, ENTRY)
    log.close()
    (path,) = log.files()
    path.rename(tmp_path / "kept")
    path.write_bytes(FOREIGN)  # someone's file under the name the next log of this process would take
    with pytest.raises(FileExistsError):
        CacheLog(folder, "r1").append("b" * 64, ENTRY)
    assert path.read_bytes() == FOREIGN


# -- the record itself ---------------------------------------------------------------


def test_a_file_under_the_record_s_name_is_never_written_to(tmp_path):
    (tmp_path / fileio.RECORD_NAME).write_bytes(FOREIGN)
    with pytest.raises(OutputError, match=r"\.vision-torsion-files: not replaced: vision-torsion keeps its "
                                          r"record of the files it wrote under this name") as err:
        fileio.atomic_write_text(tmp_path / "a.txt", "x")
    assert err.value.reason == "not_ours"
    assert (tmp_path / fileio.RECORD_NAME).read_bytes() == FOREIGN


def test_check_replaceable_names_the_file_and_force(tmp_path):
    (tmp_path / "summary.json").write_bytes(FOREIGN)
    with pytest.raises(OutputError, match=r"summary\.json: not replaced: vision-torsion did not write this "
                                          r"file \(or it was changed since\); move it away, choose another "
                                          r"output folder, or give --force") as err:
        fileio.check_replaceable([tmp_path / "summary.json", tmp_path / "missing.json"])
    assert err.value.reason == "not_ours"
    fileio.check_replaceable([tmp_path / "summary.json"], force=True)


def test_a_long_record_is_compacted_to_the_files_still_there(tmp_path):
    stem = "x" * 200
    for k in range(1500):  # ~250 bytes a line: past the compaction size (256 KiB)
        fileio.atomic_write_text(tmp_path / f"{stem}{k % 3}.txt", str(k), durable=False)
    (tmp_path / f"{stem}2.txt").unlink()
    fileio.atomic_write_text(tmp_path / "last.txt", "y", durable=False)
    lines = (tmp_path / fileio.RECORD_NAME).read_text().splitlines()
    assert len(lines) < 1500
    assert all(fileio.is_ours(tmp_path / f"{stem}{k}.txt") for k in (0, 1))
    assert fileio.is_ours(tmp_path / "last.txt")
    shutil.copy(tmp_path / "last.txt", tmp_path / "copy.txt")
    assert not fileio.is_ours(tmp_path / "copy.txt")  # same bytes, but not written here


def test_a_figure_in_the_way_stops_the_whole_report_set(capsys, home):
    out = home / "out"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "phase_stiffness.svg").write_bytes(FOREIGN)
    code, _, err = run(capsys, *_argv(home, out, "report"))
    assert code == 2
    refused_by_name(err, out / "figures" / "phase_stiffness.svg")
    # the report's files are replaced together or not at all: none was written
    assert not any((out / name).exists() for name in ("report.html", "summary.json", "stiffness_table.csv"))
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["phase_stiffness.svg"]


def test_a_file_whose_name_is_not_utf8_is_proven_ours(tmp_path):
    name = b"caf\xe9.csv".decode("utf-8", "surrogateescape")  # a Latin-1 name on a UTF-8 system
    fileio.atomic_write_text(tmp_path / name, "a")
    assert fileio.is_ours(tmp_path / name)
    fileio.atomic_write_text(tmp_path / name, "b")  # its own file: replaced without --force
    assert (tmp_path / name).read_text() == "b"
