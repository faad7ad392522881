"""Faults and bad input, as a new user and a busy lab meet them (issue 16).

Every case runs the command line in this process (``cli.main``) on a corpus made
here at run time (no binary fixtures) and checks the contract:

- no Python traceback reaches the user, and the exit status says what happened
  (1 an item failed, 2 unusable input or output, 3 internal error);
- the message names the file, row or field and the reason;
- nothing already measured is lost (a failed write leaves the cache);
- inputs are unchanged (hashed before and after).
"""

from __future__ import annotations

import os
import re
import stat
import struct
import subprocess
import zlib
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from helpers import draw_target, make_session, mount_tmpfs, run_cli, tree_digest

from vision_torsion import fileio
from vision_torsion.cli import main
from vision_torsion.errors import ImageReadError, OutputError
from vision_torsion.images import MAX_IMAGE_PIXELS, decode_image, load_image

# -- helpers ------------------------------------------------------------------------


run = run_cli


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bytes(width: int, height: int, *, bit_depth=8, rows: bytes | None = None, extra=()) -> bytes:
    """A grey PNG written by hand (so its header can claim anything)."""
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, 0, 0, 0, 0)
    if rows is None:
        rows = b"".join(b"\0" + b"\x80" * (width * bit_depth // 8) for _ in range(min(height, 4)))
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + b"".join(extra)
            + _chunk(b"IDAT", zlib.compress(rows)) + _chunk(b"IEND", b""))


@pytest.fixture
def folder(tmp_path):
    """A measure folder: a reference and four rotated targets (200x150 px PNGs)."""
    d = tmp_path / "images"
    d.mkdir()
    for i, angle in enumerate((0.0, 1.0, 2.0, 3.0, 4.0)):
        name = "reference.png" if i == 0 else f"img_{i:03d}.png"
        cv2.imwrite(str(d / name), draw_target(angle))
    return d


def measure(capsys, folder, *extra):
    return run(capsys, "measure", folder, "--reference", folder / "reference.png",
               "-o", folder.parent / "out", *extra)


def angles(folder):
    return pd.read_csv(folder.parent / "out" / "angles.csv", keep_default_na=False).set_index("image")


def jpeg_bytes(angle=0.0, quality=95) -> bytes:
    ok, enc = cv2.imencode(".jpg", draw_target(angle), [cv2.IMWRITE_JPEG_QUALITY, quality])
    return enc.tobytes()


# -- images: one odd file never stops a batch --------------------------------------------


@pytest.mark.parametrize("name, data, reason", [
    ("img_005.png", lambda: png_bytes(1, 1), r"image too small \(1x1 px; at least 8x8 px needed\)"),
    ("img_006.png", lambda: png_bytes(50000, 50000),
     r"image larger than the limit \(50000x50000 px = 2500 Mpx; at most 268 Mpx\)"),
    ("img_007.png", lambda: b"", r"empty file \(0 bytes\)"),
    ("img_008.png", lambda: b"\x89PNG\r\n\x1a\n" + b"\0" * 40, r"truncated PNG"),
])
def test_one_odd_image_is_that_image_s_failure(capsys, folder, name, data, reason):
    (folder / name).write_bytes(data())
    before = tree_digest(folder)
    code, out, err = measure(capsys, folder)
    assert code == 1
    table = angles(folder)
    assert table.loc[name, "status"] == "failed"
    assert pd.Series(table.loc[name, "message"]).str.contains(reason).all()
    assert (table.drop(index=name)["status"] == "ok").all()  # the rest measured
    assert name in err and "failed" in err
    assert tree_digest(folder) == before


def test_a_huge_header_is_refused_before_decoding():
    with pytest.raises(ImageReadError, match=r"x\.png: image larger than the limit"):
        decode_image(png_bytes(40000, 40000), name="x.png")
    assert MAX_IMAGE_PIXELS == 1 << 28


def test_a_non_utf8_file_name_is_measured_and_written_escaped(capsys, folder):
    os.rename(folder / "img_002.png", os.path.join(os.fsencode(folder), b"caf\xe9.png"))
    code, out, err = measure(capsys, folder)
    assert code == 0
    table = angles(folder)
    assert table.loc["caf\\xe9.png", "status"] == "ok"


# -- corrupt JPEGs are never measured as good ----------------------------------------------


@pytest.mark.parametrize("where, length", [(0.5, 20), (0.35, 1), (0.6, 4), (0.8, 64)])
def test_a_partly_corrupted_jpeg_fails_with_the_decoder_s_words(capsys, tmp_path, where, length):
    d = tmp_path / "jpegs"
    d.mkdir()
    for i, angle in enumerate((0.0, 1.0, 2.0)):
        (d / f"img_{i}.jpg").write_bytes(jpeg_bytes(angle))
    raw = bytearray(jpeg_bytes(3.0))
    start = int(len(raw) * where)
    for k in range(start, start + length):
        raw[k] ^= 0x5A
    (d / "img_3.jpg").write_bytes(bytes(raw))
    code, out, err = run(capsys, "measure", d, "--reference", d / "img_0.jpg", "-o", tmp_path / "out")
    table = pd.read_csv(tmp_path / "out" / "angles.csv", keep_default_na=False).set_index("image")
    row = table.loc["img_3.jpg"]
    # either the decoder noticed (failed, with its words), or the damage left the
    # measured angle within 5 sigma of the truth: never a wrong angle with status ok
    if row["status"] == "failed":  # by the decoder, with its words, or by the marker checks
        assert code == 1
        assert ("img_3.jpg: corrupt JPEG data (the decoder said: " in row["message"]
                or "img_3.jpg: found " in row["message"]), row["message"]
    else:
        assert abs(float(row["angle_deg"]) - 3.0) < 5 * float(row["angle_std_deg"]) + 0.01


def test_the_corrupt_jpeg_of_the_issue_is_detected():
    rng = np.random.default_rng(1)
    image = draw_target(3.0, width=1400, height=1000, centre=(700.4, 500.6), arm_px=300, radius_px=35)
    noisy = np.clip(image + rng.normal(0, 2, image.shape), 0, 255).astype(np.uint8)
    raw = bytearray(cv2.imencode(".jpg", noisy, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes())
    for k in range(len(raw) // 2, len(raw) // 2 + 20):
        raw[k] ^= 0x5A
    with pytest.raises(ImageReadError, match=r"a\.jpg: corrupt JPEG data \(the decoder said: "
                                             r"Corrupt JPEG data: "):
        decode_image(bytes(raw), name="a.jpg")


# -- formats users have ----------------------------------------------------------------------


def test_bytes_after_the_end_are_accepted_with_a_note(tmp_path, caplog):
    png = cv2.imencode(".png", draw_target(1.0))[1].tobytes()
    jpg = jpeg_bytes(1.0)
    a = decode_image(png + b"\0" * 100, name="a.png")
    b = decode_image(jpg + b"camera trailer" * 20, name="b.jpg")
    assert np.array_equal(a.data, decode_image(png, name="x").data)
    assert np.array_equal(b.data, decode_image(jpg, name="y").data)
    assert "a.png: 100 bytes after the end of the PNG (its IEND chunk) ignored" in caplog.text
    assert "b.jpg: 280 bytes after the end of the JPEG (its end-of-image marker) ignored" in caplog.text


def test_a_truly_truncated_png_is_still_called_truncated():
    png = cv2.imencode(".png", draw_target(1.0))[1].tobytes()
    with pytest.raises(ImageReadError, match=r"t\.png: truncated PNG \(no IEND chunk at the end\)"):
        decode_image(png[:-30], name="t.png")


def test_an_msb_aligned_12_bit_png_is_accepted(tmp_path):
    rng = np.random.default_rng(3)
    twelve = rng.integers(0, 4096, size=(20, 30)).astype(np.uint16)
    twelve[0, 0] = 4095
    shifted = (twelve << 4).astype(">u2")  # MSB-aligned, big-endian as PNG stores it
    rows = b"".join(b"\0" + shifted[y].tobytes() for y in range(20))
    raw = png_bytes(30, 20, bit_depth=16, rows=rows, extra=[_chunk(b"sBIT", b"\x0c")])
    path = tmp_path / "msb.png"
    path.write_bytes(raw)
    img = load_image(path)
    assert img.bit_depth == 12
    assert np.array_equal(img.data, twelve.astype(np.float32))


def test_an_lsb_aligned_12_bit_png_with_sbit_stays_as_it_is(tmp_path):
    twelve = np.arange(600, dtype=np.uint16).reshape(20, 30) * 6
    rows = b"".join(b"\0" + twelve.astype(">u2")[y].tobytes() for y in range(20))
    img = decode_image(png_bytes(30, 20, bit_depth=16, rows=rows, extra=[_chunk(b"sBIT", b"\x0c")]),
                       name="lsb.png")
    assert img.bit_depth == 12 and np.array_equal(img.data, twelve.astype(np.float32))


# -- output errors are user errors ----------------------------------------------------------------


def test_a_file_where_the_output_folder_should_be(capsys, folder, tmp_path):
    (tmp_path / "out").write_text("not a folder")
    before = tree_digest(folder)
    code, out, err = measure(capsys, folder)
    assert code == 2
    assert err.strip() == f"error: {tmp_path / 'out'}: cannot write results there: it is a file, not a folder"
    assert tree_digest(folder) == before


def test_a_folder_where_the_result_file_should_be(capsys, folder, tmp_path):
    (tmp_path / "out" / "angles.csv").mkdir(parents=True)
    code, out, err = measure(capsys, folder)
    assert code == 2
    assert f"{tmp_path / 'out' / 'angles.csv'}: cannot write (a folder is in the way" in err
    assert len(err.strip().splitlines()) == 1


@pytest.fixture
def small_disk(tmp_path):
    """A mounted 256 kB tmpfs (needs root; skipped where mounting is not allowed)."""
    mounted = []

    def make(name, options):
        p = tmp_path / name
        if not mount_tmpfs(p, options):
            pytest.skip("cannot mount a tmpfs here (needs root)")
        mounted.append(p)
        return p

    yield make
    for p in mounted:
        subprocess.run(["umount", "-l", str(p)], capture_output=True, timeout=20)


def test_a_read_only_output_folder_is_refused_before_measuring(capsys, folder, small_disk):
    ro = small_disk("ro", "ro,size=256k")
    code, out, err = measure(capsys, folder, "-o", ro / "results")
    assert code == 2
    assert err.strip() == (f"error: {ro / 'results'}: cannot create the output folder "
                           "(read-only file system)")


def test_a_full_disk_is_refused_before_measuring(capsys, folder, small_disk):
    full = small_disk("full", "size=256k")
    with open(full / "filler", "wb") as f:  # fill it
        try:
            f.write(b"\0" * (1 << 20))
        except OSError:
            pass
    code, out, err = measure(capsys, folder, "-o", full / "results")
    assert code == 2
    assert f"{full / 'results'}: " in err and "no space left on the device" in err


def test_a_failed_write_of_process_keeps_the_measured_results(capsys, tmp_path):
    session = tmp_path / "session"
    plan, _ = make_session(session, orientations=(0,))
    before = tree_digest(session)
    out = tmp_path / "results"
    (out / "measurements.csv").mkdir(parents=True)  # the table cannot be written
    code, _, err = run(capsys, "process", session, "-o", out, "--jobs", "1")
    assert code == 2 and "measurements.csv: cannot write" in err
    assert tree_digest(session) == before
    (out / "measurements.csv").rmdir()
    code, stdout, _ = run(capsys, "process", session, "-o", out, "--jobs", "1")
    assert code == 0
    assert f"0 measured, {len(plan.rows)} from the cache" in stdout  # nothing was lost


def test_results_follow_the_umask(capsys, folder, tmp_path):
    old = os.umask(0o022)
    try:
        fileio.file_mode.cache_clear()
        code, _, _ = measure(capsys, folder)
        mode = stat.S_IMODE((tmp_path / "out" / "angles.csv").stat().st_mode)
    finally:
        os.umask(old)
        fileio.file_mode.cache_clear()
    assert code == 0 and mode == 0o644


def test_a_set_of_files_is_replaced_whole_or_not_at_all(tmp_path):
    out = tmp_path / "set"
    with fileio.output_set():
        fileio.atomic_write_text(out / "a.txt", "old a")
        fileio.atomic_write_text(out / "b.txt", "old b")
    (out / "c.txt").mkdir()  # one file of the new set cannot be written
    with pytest.raises(OutputError, match=r"c\.txt: cannot write \(a folder is in the way where the "
                                          r"file should be\); none of the 3 result files"):
        with fileio.output_set():
            fileio.atomic_write_text(out / "a.txt", "new a")
            fileio.atomic_write_text(out / "b.txt", "new b")
            fileio.atomic_write_text(out / "c.txt", "new c")
    assert (out / "a.txt").read_text() == "old a" and (out / "b.txt").read_text() == "old b"
    assert sorted(p.name for p in out.iterdir()) == [fileio.RECORD_NAME, "a.txt", "b.txt", "c.txt"]  # no temporaries


def test_stiffness_with_one_plot_locked_replaces_nothing(capsys, tmp_path):
    rng = np.random.default_rng(0)
    t = np.linspace(0, 20, 2001)
    torque = 10 * np.sin(2 * np.pi * t / 10)
    angle = torque / 3000 * 57.3 + rng.normal(0, 1e-4, t.size)
    data = tmp_path / "run.csv"
    pd.DataFrame({"time_s": t, "torque_nm": torque, "input_angle_deg": angle * 50}).to_csv(data, index=False)
    rig = tmp_path / "rig.toml"
    rig.write_text("[rig]\ntransmission_ratio = 50\n")
    out = tmp_path / "stiff"
    code, _, err = run(capsys, "stiffness", data, "--rig", rig, "-o", out)
    if code != 0:
        pytest.skip(f"this record does not analyse: {err}")
    before = tree_digest(out)
    (out / "stiffness_torque.png").unlink()
    (out / "stiffness_torque.png").mkdir()  # "locked"
    code, _, err = run(capsys, "stiffness", data, "--rig", rig, "-o", out, "--order", "5")
    assert code == 2
    assert "stiffness_torque.png: cannot write" in err and "none of the" in err
    after = tree_digest(out)
    del before["stiffness_torque.png"], after["stiffness_torque.png"]
    assert after == before  # the other files are the old ones, untouched


# -- check-accuracy never writes into its input folder ----------------------------------------


def test_check_accuracy_refuses_its_input_folder_as_output(capsys, folder):
    (folder / "reference.csv").write_text(
        "image,reference_angle_deg\n" + "".join(f"{n},{a}\n" for n, a in
        [("reference.png", 0), ("img_001.png", 1), ("img_002.png", 2), ("img_003.png", 3)]))
    before = tree_digest(folder)
    code, out, err = run(capsys, "check-accuracy", folder, "-o", folder)
    assert code == 2
    assert "the output folder cannot be the image folder itself" in err
    assert tree_digest(folder) == before


# -- the command line ------------------------------------------------------------------------


def test_an_internal_error_is_one_line_and_status_3(capsys, folder, monkeypatch):
    import vision_torsion.measure as measure_module

    def broken(*args, **kwargs):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(measure_module, "measure_folder", broken)
    code, out, err = measure(capsys, folder)
    assert code == 3
    assert err.strip().splitlines() == [
        "internal error in measure (vision_torsion.tests.broken): ZeroDivisionError: division by zero; "
        "please report it (run again with --debug for the traceback)"] or (
        err.startswith("internal error in measure") and len(err.strip().splitlines()) == 1)
    code = main(["measure", str(folder), "--reference", str(folder / "reference.png"), "--debug"])
    assert code == 3 and "Traceback" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["-q", "measure"], ["measure", "-q"]])
def test_quiet_before_or_after_the_subcommand_silences_stdout(capsys, folder, argv):
    code = main([*argv, str(folder), "--reference", str(folder / "reference.png"),
                 "-o", str(folder.parent / "out")])
    out, err = capsys.readouterr()
    assert code == 0 and out == "" and err == ""


def test_verbose_before_the_subcommand_shows_the_tool_s_own_debug(capsys, folder, caplog):
    import logging

    code = main(["-v", "measure", str(folder), "--reference", str(folder / "reference.png"),
                 "-o", str(folder.parent / "out")])
    assert code == 0
    assert logging.getLogger("vision_torsion").getEffectiveLevel() == logging.DEBUG
    assert logging.getLogger("matplotlib").getEffectiveLevel() >= logging.WARNING


def test_synth_accuracy_refuses_a_non_empty_folder_without_force(capsys, tmp_path, scene_file):
    out = tmp_path / "acc"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code, _, err = run(capsys, "synth", "accuracy", out, "--scene", scene_file("small_target"),
                       "--angles", "1")
    assert code == 2 and "folder exists and is not empty; use --force" in err
    code, _, _ = run(capsys, "synth", "accuracy", out, "--scene", scene_file("small_target"),
                     "--angles", "1", "--force")
    assert code == 0 and (out / "notes.txt").read_text() == "mine"


def test_floats_are_written_short(tmp_path):
    frame = pd.DataFrame({"x": [0.36 * 0.981, float("nan"), 1e-20], "n": [1, 2, 3]})
    path = fileio.write_csv(tmp_path / "f.csv", frame)
    assert path.read_text() == "x,n\n0.35316,1\n,2\n1e-20,3\n"
    assert frame["x"][0] == 0.36 * 0.981  # the caller's frame is not changed


# -- text inputs: separators, byte-order marks, encodings --------------------------------


@pytest.fixture
def small_session(tmp_path):
    folder = tmp_path / "session"
    make_session(folder, orientations=(0,))
    return folder


def _rewrite_manifest(folder, transform):
    path = folder / "manifest.csv"
    path.write_bytes(transform(path.read_text()))


def _process(capsys, folder, tmp_path):
    return run(capsys, "process", folder, "-o", tmp_path / "results", "--jobs", "1")


@pytest.mark.parametrize("transform", [
    lambda t: t.replace(",", ";").encode(),
    lambda t: t.replace(",", ";").replace("0.02", "0,02").replace("0.04", "0,04").encode(),
    lambda t: t.replace(",", "\t").encode(),
    lambda t: b"\xef\xbb\xbf" + t.encode(),
], ids=["semicolon", "semicolon-decimal-comma", "tab", "bom"])
def test_manifests_as_spreadsheets_write_them_are_accepted(capsys, small_session, tmp_path, transform):
    reference = _process(capsys, small_session, tmp_path / "a")
    assert reference[0] == 0
    expected = (tmp_path / "a" / "results" / "measurements.csv").read_text()
    _rewrite_manifest(small_session, transform)
    before = tree_digest(small_session)
    code, _, err = _process(capsys, small_session, tmp_path / "b")
    assert code == 0, err
    got = (tmp_path / "b" / "results" / "measurements.csv").read_text()
    assert got.splitlines()[1:] == expected.splitlines()[1:]  # same rows, same numbers
    assert tree_digest(small_session) == before


def test_a_manifest_in_another_encoding_names_the_line(capsys, small_session, tmp_path):
    _rewrite_manifest(small_session, lambda t: (t.rstrip("\n") + ",\n").replace(
        "mass_kg\n", "mass_kg,remark\n", 1).replace(",\n", ",ok\n").encode()[:-4]
        + "Gewicht geprüft\n".encode("latin-1"))
    code, _, err = _process(capsys, small_session, tmp_path)
    assert code == 2
    n = len((small_session / "manifest.csv").read_bytes().splitlines())
    assert f"manifest.csv: line {n}: not UTF-8 text (byte 0xfc at column" in err
    assert "save the manifest as UTF-8" in err


def test_a_reference_table_with_a_bom_and_semicolons_is_read(tmp_path):
    from vision_torsion.calibration.accuracy import read_reference_table

    d = tmp_path / "check"
    d.mkdir()
    for i in range(3):
        cv2.imwrite(str(d / f"i{i}.png"), draw_target(float(i)))
    (d / "reference.csv").write_bytes(b"\xef\xbb\xbfimage;reference_angle_deg\ni0.png;0\ni1.png;1\ni2.png;2\n")
    table = read_reference_table(d)
    assert list(table["image"]) == ["i0.png", "i1.png", "i2.png"]


# -- plausibility: unit slips --------------------------------------------------------------


def _set_row(folder, line, column, value):
    path = folder / "manifest.csv"
    rows = path.read_text().splitlines()
    header = rows[0].split(",")
    fields = rows[line - 1].split(",")
    fields[header.index(column)] = value
    rows[line - 1] = ",".join(fields)
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.parametrize("value, message", [
    ("40", r"line 3: mass 40 kg on each pan is 2000 pieces, more than the 2 \(0.04 kg\) the protocol "
           r"loads for max_torque_nm 0.03924 N·m: grams\? \(write kg\)"),
    ("0.06", r"line 3: mass 0.06 kg on each pan is 3 pieces, more than the 2 \(0.04 kg\)"),
    ("0.025", r"line 3: mass_kg 0.025 kg is not a whole number of 0.02 kg pieces \(1.25 pieces\)"),
])
def test_implausible_masses_are_errors_naming_the_line(capsys, small_session, tmp_path, value, message):
    _set_row(small_session, 3, "mass_kg", value)
    code, _, err = _process(capsys, small_session, tmp_path)
    assert code == 2
    assert re.search(message, err), err
    assert not (tmp_path / "results" / "measurements.csv").exists()


def test_a_measured_torque_in_n_mm_is_an_error(capsys, small_session, tmp_path):
    path = small_session / "manifest.csv"
    lines = path.read_text().splitlines()
    lines[0] += ",torque_nm,torque_std_nm"
    lines = [lines[0]] + [line + ",," for line in lines[1:]]
    lines[2] = lines[2][:-2] + ",39.2,0.1"
    path.write_text("\n".join(lines) + "\n")
    code, _, err = _process(capsys, small_session, tmp_path)
    assert code == 2 and re.search(r"line 3: torque_nm 39.2 N·m is 999 times the protocol's "
                                   r"max_torque_nm 0.03924 N·m: N·mm\? \(write N·m\)", err), err


@pytest.mark.parametrize("key, value, message", [
    ("arm_radius_m", "50", r"rig.arm_radius_m = 50 m is outside 0.001..2 m: millimetres\?"),
    ("gravity_m_per_s2", "981", r"rig.gravity_m_per_s2 = 981 m/s² is outside the Earth's 9.76..9.84 m/s²: cm/s²\?"),
])
def test_implausible_rig_numbers_are_errors_with_the_unit(capsys, small_session, tmp_path, key, value, message):
    path = small_session / "session.toml"
    text = path.read_text()
    text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text) if re.search(rf"(?m)^{key} = ", text) \
        else text.replace("[rig]\n", f"[rig]\n{key} = {value}\n")
    path.write_text(text)
    code, _, err = _process(capsys, small_session, tmp_path)
    assert code == 2 and re.search(message, err), err


# -- worker processes end with the main process ----------------------------------------------


def _children(pid: int) -> set[int]:
    """Every descendant of `pid` (Linux /proc)."""
    found, todo = set(), [pid]
    while todo:
        p = todo.pop()
        try:
            text = Path(f"/proc/{p}/task/{p}/children").read_text()
        except OSError:
            continue
        kids = {int(k) for k in text.split()}
        todo.extend(kids - found)
        found |= kids
    return found


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_workers_exit_when_the_main_process_is_killed(tmp_path):
    import signal
    import sys
    import time

    from test_session_core import draw

    folder = tmp_path / "session"
    make_session(folder, orientations=(0, 60, 120), steps=8, draw=draw)
    script = ("import sys; from vision_torsion.session import process_session; "
              "process_session(sys.argv[1], out_dir=sys.argv[2], jobs=4)")
    proc = subprocess.Popen([sys.executable, "-c", script, str(folder), str(tmp_path / "out")])
    workers: set[int] = set()
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None and len(workers) < 4:
            workers = _children(proc.pid)
            time.sleep(0.02)
        if proc.poll() is not None:
            pytest.skip("the run finished before its workers were seen")
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    deadline = time.monotonic() + 10
    alive = workers
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = {w for w in alive if Path(f"/proc/{w}").exists()
                 and Path(f"/proc/{w}/stat").read_text().split(")")[-1].split()[0] != "Z"}
    assert not alive, f"worker processes still running after the main process died: {alive}"


# -- ready scenes and specs by name -----------------------------------------------------------


def test_ready_scenes_and_specs_are_named(capsys, tmp_path):
    from vision_torsion.calibration.accuracy import load_spec
    from vision_torsion.errors import SceneError
    from vision_torsion.resources import SCENES, SPECS, available
    from vision_torsion.synthetic import load_scene

    assert {"standard", "jpeg", "paper_session", "small_target"} <= set(available(SCENES))
    assert set(available(SPECS)) >= {"rotary_stage", "synthetic_selfcheck"}
    assert load_scene("standard").image.width == 1400
    assert load_spec("rotary_stage").tolerance_deg == 0.02
    with pytest.raises(SceneError, match=r"standrd: no such file, and no ready scene of that name "
                                         r"\(ready: distractors, jpeg, "):
        load_scene("standrd")
    code, _, _ = run(capsys, "synth", "accuracy", tmp_path / "a", "--scene", "small_target", "--angles", "1")
    assert code == 0 and (tmp_path / "a" / "reference.csv").is_file()


@pytest.mark.parametrize("name", ["binding.json", "correction.json"])
def test_json_inputs_with_a_bom_or_another_encoding(tmp_path, name):
    from vision_torsion.correction import load_correction
    from vision_torsion.errors import CalibrationError, SessionError
    from vision_torsion.session.binding import load_binding

    path = tmp_path / name
    path.write_bytes("{\"k\": \"é\"}".encode("latin-1"))
    error, load = ((SessionError, lambda: load_binding(tmp_path)) if name == "binding.json"
                   else (CalibrationError, lambda: load_correction(path)))
    with pytest.raises(error, match=rf"{name}: line 1: not UTF-8 text \(byte 0xe9 at column 8\)"):
        load()
    path.write_bytes(b"\xef\xbb\xbf{}")  # a BOM is read past: the complaint is about the content
    with pytest.raises(error) as info:
        load()
    assert "BOM" not in str(info.value) and "UTF-8" not in str(info.value)


# -- a marker fit far above the noise marks the image suspect ------------------------------


def test_a_damaged_block_on_a_marker_makes_the_image_suspect(capsys, tmp_path):
    from vision_torsion.pair import measure_pair
    from vision_torsion.synthetic import load_scene, render

    scene = load_scene("standard")
    d = tmp_path / "images"
    d.mkdir()
    for i, angle in enumerate((0.0, 1.0, 2.0, 3.0, 4.0)):
        image = render(scene, angle, seed=i).image
        if i == 3:
            # a 24x24 block across marker 1's edge displaced by 1 px, as damaged JPEG
            # blocks: too much of the edge for the occluder cut, which takes a 16x16
            # block (test_pixelfit) and leaves the marker right; the centre moves
            # 0.2 px, under the hidden-arc check's limit (by 3 px: 0.5 px, occluded)
            m = measure_pair(image).first
            x0, y0 = int(m.x_px + m.radius_px - 12), int(m.y_px - 12)
            image = np.array(image, dtype=np.float64)
            image[y0:y0 + 24, x0:x0 + 24] = np.roll(image[y0:y0 + 24, x0:x0 + 24], 1, axis=1)
        cv2.imwrite(str(d / f"img_{i}.png"), np.clip(np.rint(image), 0, 255).astype(np.uint8))
    before = tree_digest(d)
    code, _, err = run(capsys, "measure", d, "--reference", d / "img_0.png", "-o", tmp_path / "out")
    table = pd.read_csv(tmp_path / "out" / "angles.csv", keep_default_na=False).set_index("image")
    assert code == 1
    assert list(table["status"]) == ["ok", "ok", "ok", "suspect", "ok"]
    assert re.match(r"suspect: marker \d's edge residual [\d.]+ px is [\d.]+ times the sequence's typical",
                    table.loc["img_3.png", "message"])
    assert table.loc["img_3.png", "angle_deg"] != ""  # the angle is kept to look at
    assert "img_3.png: suspect: marker" in err
    assert tree_digest(d) == before


def test_clean_sequences_of_every_ready_scene_raise_no_flag():
    from vision_torsion.pair import measure_pair
    from vision_torsion.quality import residual_flags
    from vision_torsion.resources import SCENES, available
    from vision_torsion.settings import MeasureSettings
    from vision_torsion.synthetic import load_scene, render

    for name in set(available(SCENES)) - {"paper_session"}:  # that one is the standard scene's geometry
        scene = load_scene(name)
        # a two-radii target (two_radii.toml) is measured as one
        settings = MeasureSettings(polarity=scene.markers.polarity,
                                   pair="distinct" if scene.markers.radii_px else "largest")
        pairs = [measure_pair(render(scene, angle, seed=7 + k).image, settings=settings)
                 for k, angle in enumerate((0.0, 3.0, 11.0, 27.0))]
        assert residual_flags(pairs) == [""] * 4, name


def test_the_typical_residual_is_the_median_of_the_sequence():
    """The sequence's typical residual is the median of its images' mean marker residuals
    (the mean of the middle two for an even count), as statistics.median gives it."""
    import statistics
    from dataclasses import replace

    from vision_torsion.markers import Marker
    from vision_torsion.pair import PairMeasurement
    from vision_torsion.quality import residual_flags

    def pair(r1, r2):
        m = Marker(x_px=10.0, y_px=10.0, radius_px=5.0, residual_rms_px=r1)
        return PairMeasurement(first=m, second=replace(m, x_px=50.0, residual_rms_px=r2))

    residuals = [(0.1, 0.13), (0.2, 0.11), (0.17, 0.3), (0.12, 0.9)]
    typical = statistics.median((a + b) / 2 for a, b in residuals)  # 0.195, between two images
    flags = residual_flags([pair(*r) for r in residuals])
    assert flags[:3] == ["", "", ""]
    assert flags[3] == (f"suspect: marker 2's edge residual 0.9 px is {0.9 / typical:.1f} times the sequence's "
                        f"typical {typical:.3g} px (a damaged or corrupt image, or something on the marker?)")
    odd = residuals[:2] + residuals[3:]  # median 0.155: one image's own level
    assert f"typical {statistics.median((a + b) / 2 for a, b in odd):.3g} px" in residual_flags(
        [pair(*r) for r in odd])[2]


def test_a_target_marker_beside_a_dark_surround_makes_its_image_suspect():
    """A marker whose ring held a region as dark as itself (Marker.steep_cut: its centre
    good to 0.4 px, not to its std) makes its image suspect, even in a sequence
    too short to have a typical residual; the other images stay clean."""
    from dataclasses import replace

    from vision_torsion.markers import Marker
    from vision_torsion.pair import PairMeasurement
    from vision_torsion.quality import STEEP_CUT_PX, residual_flags

    m = Marker(x_px=10.0, y_px=10.0, radius_px=5.0, residual_rms_px=0.1)
    clean = PairMeasurement(first=m, second=replace(m, x_px=50.0))
    beside = PairMeasurement(first=m, second=replace(m, x_px=50.0, steep_cut=True))
    flags = residual_flags([clean, beside, None])
    assert flags[0] == "" and flags[2] == ""
    assert flags[1].startswith("suspect: marker 2 lies beside a region as dark (bright) as itself")
    # the same bound as the marker's own caveat (markers.STEEP_CUT_MESSAGE)
    assert f"off by up to {STEEP_CUT_PX} px" in flags[1]
    assert residual_flags([clean, clean, clean, beside])[3] == flags[1]  # with a typical residual too


def test_the_pandas_free_csv_writer_writes_what_pandas_writes(tmp_path):
    columns = ["image", "mass_kg", "torque_nm", "angle_deg", "status", "message"]
    records = [
        {"image": "images/a.png", "mass_kg": "0.36", "torque_nm": 0.36 * 0.981, "angle_deg": float("nan"),
         "status": "failed", "message": 'a "quoted", comma message'},
        {"image": "images/b.png", "mass_kg": "0", "torque_nm": -0.0, "angle_deg": 1e-20,
         "status": "ok", "message": ""},
        {"image": "images/c.png", "mass_kg": "", "torque_nm": 12345.678901234567, "angle_deg": -3.5,
         "status": "suspect", "message": "line one\nline two"},
    ]
    fast = fileio.write_records_csv(tmp_path / "fast.csv", columns, records).read_bytes()
    slow = fileio.write_csv(tmp_path / "pandas.csv", pd.DataFrame.from_records(records, columns=columns)).read_bytes()
    assert fast == slow


def test_plan_and_synth_refuse_an_unwritable_folder_before_writing(capsys, tmp_path):
    (tmp_path / "file").write_text("x")
    code, _, err = run(capsys, "plan", tmp_path / "file" / "session", "--max-torque", "0.36",
                       "--step-mass", "0.02", "--arm-radius", "0.05")
    assert code == 2 and "file" in err and "cannot create the output folder" in err
    code, _, err = run(capsys, "synth", "session", tmp_path / "file", "--scene", "paper_session")
    assert code == 2 and "it is a file, not a folder" in err


# -- inputs that are not regular files: refused at once, never waited on --------------------


def named_pipe(path, *, release_after_s=20.0):
    """Make a named pipe at `path`; after `release_after_s` a thread keeps opening and
    closing its writing end, so a reader wrongly waiting on it fails the test instead
    of hanging it. Returns the thread's stop event (set it at the end)."""
    import threading

    os.mkfifo(path)
    stop = threading.Event()

    def release():
        stop.wait(release_after_s)
        while not stop.wait(0.2):
            try:
                os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:  # no reader waiting (ENXIO), or the pipe already gone
                pass

    threading.Thread(target=release, daemon=True).start()
    return stop


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
@pytest.mark.parametrize("name", ["manifest.csv", "session.toml", "binding.json"])
def test_a_named_pipe_for_a_session_file_is_refused_without_waiting(capsys, small_session, tmp_path, name):
    (small_session / name).unlink(missing_ok=True)
    stop = named_pipe(small_session / name)  # opening it for reading would wait for a writer
    before = tree_digest(tmp_path)
    code, out, err = run(capsys, "process", small_session, "-o", tmp_path / "out")
    stop.set()
    assert code == 2
    assert f"{name}: not a regular file (a named pipe or a device); expected " in err
    assert tree_digest(tmp_path) == before


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_in_the_camera_folder_is_set_aside_by_bind(capsys, small_session, tmp_path):
    cam = tmp_path / "cam"
    cam.mkdir()
    for i, image in enumerate(pd.read_csv(small_session / "manifest.csv")["image"]):  # in capture order
        (small_session / image).rename(cam / f"IMG_{i + 1:04d}.png")
    stop = named_pipe(cam / "IMG_9999.png")  # reading it (a capture time, a hash) would wait
    before = tree_digest(cam)
    code, out, err = run(capsys, "bind", small_session, cam, "--by", "name")
    stop.set()
    assert code == 1  # the synthetic angles' steps give bind things to look at
    assert "IMG_9999.png: not a regular file (a named pipe or a device); not bound" in out + err
    assert tree_digest(cam) == before


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_as_an_image_is_refused_without_waiting(capsys, small_session, tmp_path):
    stop = named_pipe(tmp_path / "reference.png")  # reading it would wait for a writer
    before = tree_digest(small_session)
    code, out, err = run(capsys, "measure", small_session / "images", "--reference", tmp_path / "reference.png",
                         "-o", tmp_path / "out")
    stop.set()
    assert code == 2
    assert f"{tmp_path / 'reference.png'}: not a regular file (a named pipe or a device), not an image file" in err
    assert tree_digest(small_session) == before


# -- the output folder is never a folder of the inputs ---------------------------------------


def refused(capsys, tree, *argv) -> str:
    """Run a command that must refuse (status 2) and leave `tree` as it was; its stderr."""
    before = tree_digest(tree)
    code, _, err = run(capsys, *argv)
    assert code == 2
    assert tree_digest(tree) == before
    return err


@pytest.mark.parametrize("command", ["process", "report"])
def test_the_folder_of_the_session_s_images_is_refused_as_output(capsys, small_session, command):
    err = refused(capsys, small_session, command, small_session, "-o", small_session / "images")
    assert f"{small_session / 'images'}: the output folder cannot be a folder of the session's images; " \
           "use a folder of its own such as results/" in err


# -- a zero mass where the plan has weights ----------------------------------------------------


def test_an_unloading_step_at_zero_mass_before_its_last_names_its_line(capsys, small_session, tmp_path):
    manifest = small_session / "manifest.csv"
    rows = manifest.read_text().splitlines()
    n = next(i for i, r in enumerate(rows) if ",positive_unloading,0," in r)  # the fully loaded step
    rows[n] = rows[n].rsplit(",", 1)[0] + ",0"
    manifest.write_text("\n".join(rows) + "\n")
    before = tree_digest(tmp_path)
    code, out, err = run(capsys, "process", small_session, "-o", tmp_path / "out")
    assert code == 2
    assert re.search(rf"line {n + 1}: mass_kg 0 on step 0 of a positive_unloading row, yet step 1 \(line "
                     rf"{n + 2}\) still has 0\.02 kg on each pan; an unloading phase reaches 0 only at its "
                     "last step", err), err
    assert tree_digest(tmp_path) == before


# -- watch: a camera folder that is not there yet has not disappeared ---------------------------


def test_watch_on_a_camera_folder_not_made_yet_says_so(small_session, tmp_path):
    from vision_torsion.session.watch import Watcher

    cam = tmp_path / "cam"  # the camera makes it at its first photograph, or --camera-dir has a typo
    with Watcher(small_session, camera_dir=cam, events="poll") as w:
        assert [(e.kind, e.message) for e in w.tick()] == [
            ("folder_gone", f"{cam}: no such folder yet; waiting for it (check --camera-dir if the camera "
                            "does not make it; Ctrl-C to stop)")]
        assert w.tick() == []  # said once
        cam.mkdir()
        assert [(e.kind, e.message) for e in w.tick()] == [("folder_back", f"{cam}: the camera folder is there")]
    assert not cam.exists() or not any(cam.iterdir())


def test_a_manifest_of_more_rows_than_a_plan_may_write_is_refused_as_it_is_read(capsys, small_session, tmp_path):
    from vision_torsion.session.manifest import MAX_MANIFEST_ROWS
    from vision_torsion.session.plan import MAX_PLAN_IMAGES

    assert MAX_PLAN_IMAGES == MAX_MANIFEST_ROWS  # what plan may write, process may read
    manifest = small_session / "manifest.csv"
    n = len(manifest.read_text().splitlines()) - 1
    with manifest.open("a") as fh:  # a runaway script appending rows
        fh.writelines(f"images/x{i}.png,0,1,positive_loading,{i + 9},0.02\n" for i in range(MAX_MANIFEST_ROWS))
    before = tree_digest(tmp_path)
    code, out, err = run(capsys, "process", small_session, "-o", tmp_path / "out")
    assert code == 2
    assert f"manifest.csv: line {MAX_MANIFEST_ROWS + 2}: more than {MAX_MANIFEST_ROWS} rows, the most a session " \
           "may have (as many as a plan may write)" in err
    assert n < MAX_MANIFEST_ROWS
    assert tree_digest(tmp_path) == before


def test_a_huge_reference_table_is_refused_before_it_is_read(capsys, folder, tmp_path):
    table = folder / "reference.csv"
    with table.open("wb") as fh:  # sparse: 3 GB that take no room; read whole it took 6 GB of memory
        fh.truncate(3 << 30)
    before = tree_digest(folder, exclude=["reference.csv"]), table.stat().st_mtime_ns  # not read for the hash
    code, out, err = run(capsys, "check-accuracy", folder, "-o", tmp_path / "out")
    assert code == 2
    assert f"{table}: 3221225472 bytes, more than the 268435456 a reference table may have" in err
    assert (tree_digest(folder, exclude=["reference.csv"]), table.stat().st_mtime_ns) == before


def test_a_huge_plane_correction_json_is_refused_before_it_is_read(tmp_path):
    from vision_torsion.correction import load_correction
    from vision_torsion.errors import CalibrationError

    path = tmp_path / "plane.json"
    with path.open("wb") as fh:  # sparse: 3 GB that take no room; it was read whole
        fh.truncate(3 << 30)
    with pytest.raises(CalibrationError, match=r"plane\.json: 3221225472 bytes, more than the 268435456 a plane "
                                               r"correction file may have") as info:
        load_correction(path)
    assert info.value.reason == "too_large"


@pytest.mark.parametrize("kind", ["folder", "named pipe"])
def test_stiffness_given_a_folder_or_a_pipe_says_what_it_is(capsys, tmp_path, kind):
    data = tmp_path / "record.csv"
    if kind == "folder":
        data.mkdir()
    elif not hasattr(os, "mkfifo"):
        pytest.skip("named pipes are POSIX")
    else:
        os.mkfifo(data)
    before = tree_digest(tmp_path)
    code, out, err = run(capsys, "stiffness", data)
    assert code == 2
    assert f"{data}: not a regular file (a folder, a named pipe or a device); expected a torque-angle " \
           "record CSV" in err  # it said "no such file"
    assert tree_digest(tmp_path) == before  # no output folder made beside it


def test_a_newline_in_a_camera_file_name_cannot_forge_a_line_of_bind(capsys, small_session, tmp_path):
    cam = tmp_path / "cam"
    cam.mkdir()
    for i, image in enumerate(pd.read_csv(small_session / "manifest.csv")["image"]):
        (small_session / image).rename(cam / f"IMG_{i + 1:04d}.png")
    (cam / "IMG_0099\nerror: forged.txt").write_text("x")
    code, out, err = run(capsys, "bind", small_session, cam, "--by", "name")
    assert "set aside: IMG_0099\\nerror: forged.txt: not an image file" in err
    assert not any(line.startswith("error: forged") for line in (out + err).splitlines())


def test_a_newline_in_an_unlisted_file_name_cannot_forge_a_line_of_process(capsys, small_session, tmp_path):
    (small_session / "images" / "x\nerror: forged.png").write_bytes(cv2.imencode(".png", draw_target(0.0))[1])
    code, out, err = run(capsys, "process", small_session, "-o", tmp_path / "out")
    assert code == 0
    assert "not in the manifest: images/x\\nerror: forged.png" in err
    assert not any(line.startswith("error: forged") for line in (out + err).splitlines())


def test_a_newline_in_a_failed_image_s_name_cannot_forge_a_line_of_measure(capsys, folder):
    (folder / "y\nerror: forged.png").write_text("not an image")
    code, out, err = measure(capsys, folder)
    assert code == 1
    assert f"failed: {folder}/y\\nerror: forged.png: not a PNG, TIFF, BMP or JPEG image" in err
    assert not any(line.startswith("error: forged") for line in (out + err).splitlines())


def test_watch_shows_no_nan_for_the_first_photograph_s_step(small_session, tmp_path):
    from vision_torsion.session.watch import Watcher

    cam = tmp_path / "cam"
    cam.mkdir()
    first = pd.read_csv(small_session / "manifest.csv")["image"][0]
    (small_session / first).rename(cam / "IMG_0001.png")
    with Watcher(small_session, camera_dir=cam, settle_s=0.0, events="poll") as w:
        shots = [e for _ in range(3) for e in w.tick() if e.kind == "shot"]
    assert len(shots) == 1
    assert re.search(r"θ=[+-]\d+\.\d{4}°  Δθ=—$", shots[0].message), shots[0].message  # it said Δθ=+nan°
    assert "nan" not in shots[0].message


# -- an output folder that is a symbolic link looping on itself --------------------------------


@pytest.mark.parametrize("command", ["process", "report", "watch", "measure", "check-accuracy"])
def test_an_output_folder_that_is_a_looping_link_is_named(capsys, small_session, folder, tmp_path, command):
    loop = tmp_path / "loop"
    loop.symlink_to("loop")  # Path.resolve raised RuntimeError on it: an internal error
    (folder / "reference.csv").write_text("image,reference_angle_deg\n" + "".join(
        f"{p.name},{i}\n" for i, p in enumerate(sorted(folder.glob("*.png"), key=lambda p: p.name != "reference.png"))))
    argv = {"process": [small_session], "report": [small_session], "watch": [small_session],
            "measure": [folder, "--reference", folder / "reference.png"], "check-accuracy": [folder]}[command]
    err = refused(capsys, tmp_path, command, *argv, "-o", loop)
    assert f"{loop}: cannot create the output folder: a symbolic link that leads nowhere (it loops, or its " \
           "target is missing)" in err


# -- overlays: a folder that cannot take them is said so, not skipped -------------------------


def test_a_user_s_file_under_an_overlay_s_name_stops_the_overlays_by_name(capsys, folder, tmp_path):
    overlays = tmp_path / "overlays"
    overlays.mkdir()
    (overlays / "img_002_overlay.png").write_text("the user's own")
    before = tree_digest(overlays)
    code, out, err = measure(capsys, folder, "--overlay", overlays)
    assert code == 2  # it was 0, 'wrote 4 overlay(s)', the fifth skipped without a word
    assert f"{overlays / 'img_002_overlay.png'}: not replaced: vision-torsion did not write this file" in err
    assert tree_digest(overlays) == before  # none drawn, the user's file kept
    assert (folder.parent / "out" / "angles.csv").is_file()  # the measurements are kept


def test_bind_refuses_a_camera_folder_that_is_its_output_folder(capsys, small_session, tmp_path):
    results = small_session / "results"  # the default output folder, given as the camera's
    results.mkdir()
    for i, image in enumerate(pd.read_csv(small_session / "manifest.csv")["image"]):
        (small_session / image).rename(results / f"IMG_{i + 1:04d}.png")
    before = tree_digest(small_session)
    code, out, err = run(capsys, "bind", small_session, results)
    assert code == 2  # it measured them and wrote its cache among them
    assert f"{results}: the camera folder cannot be the output folder" in err
    assert tree_digest(small_session) == before
