"""Limits checked before work (issue 30): each refused with one line naming the
file, row or parameter, exit status 2 from the command line, no traceback.

Every input is generated here at run time (sparse files, crafted headers); nothing
outside the test's own folders is touched.
"""

from __future__ import annotations

import io
import json
import os
import re
import resource
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest
from helpers import draw_target, make_session, tree_digest

from vision_torsion import images as images_module
from vision_torsion.cli import main
from vision_torsion.errors import ImageReadError, ManifestError, RecordError, RigError, SessionError
from vision_torsion.images import MAX_IMAGE_FILE_BYTES, image_size, load_image, read_image_bytes, write_image
from vision_torsion.session.load import load_session
from vision_torsion.session.manifest import load_manifest
from vision_torsion.session.plan import MAX_PLAN_IMAGES, plan_config, plan_session
from vision_torsion.session.plausibility import MAX_STEPS_PER_PHASE
from vision_torsion.stiffness.records import read_record
from vision_torsion.stiffness.rig import RigConstants, load_rig
from vision_torsion.synthetic.measurement_tables import simulate_measurements


def run(capsys, *argv):
    """(status, stdout, stderr) of the command line; no traceback, one error line."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err and "internal error" not in err, err
    return code, out, err


@pytest.fixture
def session(tmp_path):
    folder = tmp_path / "session"
    make_session(folder, orientations=(0,))
    return folder


def _edit(path, old, new, count=1):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, count))


# -- session.toml ---------------------------------------------------------------------


def test_a_deeply_nested_session_toml_is_refused(capsys, session, tmp_path):
    (session / "session.toml").write_text("x = " + "[" * 3000 + "]" * 3000 + "\n")
    code, _, err = run(capsys, "process", session, "-o", tmp_path / "out")
    assert code == 2
    assert "session.toml: not valid TOML (tables or arrays nested deeper than 32 levels)" in err


def test_a_400_digit_integer_in_session_toml_is_refused(capsys, session, tmp_path):
    _edit(session / "session.toml", "cycles = 1", "cycles = " + "7" * 400)
    code, _, err = run(capsys, "process", session, "-o", tmp_path / "out")
    assert code == 2
    assert "session.toml: protocol.cycles is an integer beyond TOML's 64 bits" in err


@pytest.mark.parametrize("old, new, message", [
    ("step_mass_kg = 0.02", "step_mass_kg = 1e308",
     r"protocol\.step_mass_kg: must be a finite number > 0 \(kg\) \(its magnitude is limited to 1e\+12\), "
     r"got 1e\+308"),
    ("max_torque_nm = 0.03924", "max_torque_nm = 1e308",
     r"protocol\.max_torque_nm: must be a finite number > 0 \(N·m\) \(its magnitude is limited to 1e\+12\)"),
])
def test_1e308_in_session_toml_is_refused_by_key(session, old, new, message):
    _edit(session / "session.toml", old, new)

    with pytest.raises(SessionError, match=message):
        load_session(session)


def test_a_max_torque_of_millions_of_pieces_is_refused_by_process(session):
    _edit(session / "session.toml", "max_torque_nm = 0.03924", "max_torque_nm = 1e9")

    with pytest.raises(SessionError, match=rf"protocol\.max_torque_nm = 1e\+09 N·m needs 5\.1e\+10 pieces of "
                                           rf"0\.02 kg per pan, more than the {MAX_STEPS_PER_PHASE} a protocol"):
        load_session(session)


# -- plan: the same rules as process, and its size, before anything is written ------------


@pytest.mark.parametrize("argv, message", [
    (["--max-torque", "1", "--step-mass", "1e-9"],
     r"protocol\.step_mass_kg = 1e-09 kg is outside 0\.0001\.\.50 kg"),
    (["--steps", "1000000", "--step-mass", "0.02"],
     rf"protocol\.max_torque_nm = 19620 N·m needs 1e\+06 pieces of 0\.02 kg per pan, more than the "
     rf"{MAX_STEPS_PER_PHASE}"),
    (["--max-torque", "1", "--step-mass", "0.02", "--gravity", "981"],
     r"rig\.gravity_m_per_s2 = 981 m/s² is outside the Earth's 9\.76\.\.9\.84 m/s²: cm/s²\?"),
])
def test_plan_refuses_what_process_would_refuse(capsys, tmp_path, argv, message):
    out = tmp_path / "plan"
    code, _, err = run(capsys, "plan", out, "--arm-radius", "0.05", "--no-pdf", *argv)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("error: plan_session: ")

    assert re.search(message, err), err
    assert not out.exists() or not any(out.iterdir())


def test_plan_refuses_an_arm_radius_in_millimetres(tmp_path):
    with pytest.raises(SessionError, match=r"plan_session: 1 implausible value\(s\)\n  rig\.arm_radius_m = 50 m "
                                           r"is outside 0\.001\.\.2 m: millimetres\?"):
        plan_session(plan_config(max_torque_nm=1.0, step_mass_kg=0.02, arm_radius_m=50), tmp_path)
    assert not any(tmp_path.iterdir())


def test_plan_size_is_checked_before_writing(tmp_path):
    orientations = tuple(range(0, 360, 1))  # 360 orientations x (2 + 4 x 100 steps x 1 cycle)
    with pytest.raises(SessionError, match=rf"plan_session: 144720 images \(360 orientation\(s\) × \(2 \+ 4 phases × "
                                           rf"100 steps × 1 cycle\(s\)\)\), more than the {MAX_PLAN_IMAGES} a plan"):
        plan_session(plan_config(steps=100, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=orientations),
                                 tmp_path)
    assert not any(tmp_path.iterdir())


def test_plan_steps_must_be_whole(tmp_path):
    with pytest.raises(SessionError, match=r"plan_config: steps must be a whole number >= 1, got 2\.5"):
        plan_session(plan_config(steps=2.5, step_mass_kg=0.02, arm_radius_m=0.05), tmp_path)


# -- manifest ----------------------------------------------------------------------------


def test_a_manifest_cell_over_the_csv_field_limit_names_its_line(capsys, session, tmp_path):
    manifest = session / "manifest.csv"
    lines = manifest.read_text().splitlines(keepends=True)
    lines[3] = lines[3].rstrip("\n") + ',"unclosed note\n'
    text = lines[0].rstrip("\n") + ",notes\n" + "".join(
        line if i == 3 else line.rstrip("\n") + ",\n" for i, line in enumerate(lines[1:], 1))
    manifest.write_text(text + ("x" * 1000 + "\n") * 200)  # 200 kB inside one quoted field
    before = tree_digest(session)
    code, _, err = run(capsys, "process", session, "-o", tmp_path / "out")
    assert code == 2
    assert "manifest.csv: line 4: cannot be read as CSV (field larger than field limit (131072)); a field that " \
           "long is usually a quote (\") opened and never closed" in err
    assert tree_digest(session) == before


def test_a_loaded_step_with_zero_mass_is_refused(session):
    manifest = session / "manifest.csv"
    rows = manifest.read_text().splitlines()
    n = next(i for i, r in enumerate(rows) if ",positive_loading,1," in r)
    rows[n] = rows[n].rsplit(",", 1)[0] + ",0"
    manifest.write_text("\n".join(rows) + "\n")
    with pytest.raises(ManifestError, match=rf"line {n + 1}: mass_kg '0' on step 1 of a positive_loading row; "
                                           r"a loading step has weights on its pans"):
        load_manifest(manifest, check_files=False)


@pytest.mark.parametrize("value", ["1e308", "-1e200"])
def test_an_absurd_manifest_mass_names_its_line(session, value):
    manifest = session / "manifest.csv"
    rows = manifest.read_text().splitlines()
    rows[2] = rows[2].rsplit(",", 1)[0] + f",{value}"
    manifest.write_text("\n".join(rows) + "\n")
    with pytest.raises(ManifestError, match=r"line 3: mass_kg .*(limited to 1e\+12|is negative)"):
        load_manifest(manifest, check_files=False)


def test_an_absurd_manifest_torque_names_its_line(session):
    manifest = session / "manifest.csv"
    rows = manifest.read_text().splitlines()
    rows[0] += ",torque_nm,torque_std_nm"
    rows[1:] = [r + ",," for r in rows[1:]]
    rows[2] = rows[2][:-2] + ",1e308,0.001"
    manifest.write_text("\n".join(rows) + "\n")
    with pytest.raises(ManifestError, match=r"line 3: torque_nm must be a finite number \(its magnitude is limited "
                                           r"to 1e\+12\), got 1e\+308; expected a measured torque in N·m"):
        load_manifest(manifest, check_files=False)


def test_a_self_referencing_symlink_among_photos_is_an_error(capsys, session, tmp_path):
    image = session / load_manifest(session / "manifest.csv").rows[2].image
    image.unlink()
    image.symlink_to(image.name)
    with pytest.raises(ManifestError, match=rf"line 4: image '{image.relative_to(session).as_posix()}' is a "
                                           r"symbolic link that cannot be followed \(Too many levels"):
        load_manifest(session / "manifest.csv", missing="pending")
    code, _, err = run(capsys, "process", session, "-o", tmp_path / "out", "--jobs", "1")
    assert code == 2 and "is a symbolic link that cannot be followed" in err


# -- binding.json edited by hand ---------------------------------------------------------


@pytest.mark.parametrize("key, value, message", [
    ("missing", ["x"], r"'missing' is \['x'\]; expected a list of manifest line numbers \(whole numbers >= 2\)"),
    ("missing", 3, r"'missing' is 3; expected a list of manifest line numbers"),
    ("skipped", "IMG_1.png", r"'skipped' is 'IMG_1\.png'; expected a list of camera file names"),
    ("by", 7, r"'by' is 7; expected one of 'time', 'name', 'watch'"),
])
def test_a_hand_edited_binding_with_a_wrong_type_names_the_key(capsys, session, tmp_path, key, value, message):

    camera = tmp_path / "camera"
    camera.mkdir()
    doc = {"format": 1, "camera_dir": str(camera), "by": "time", "images": {}, "skipped": [], "missing": []}
    doc[key] = value
    (session / "binding.json").write_text(json.dumps(doc))
    code, _, err = run(capsys, "process", session, "-o", tmp_path / "out")
    assert code == 2
    assert re.search(r"binding\.json: " + message + r".*; run `vision-torsion bind` again", err), err


# -- the stiffness rig file and records ------------------------------------------------


def test_a_rig_file_with_text_for_a_list_names_the_constant(capsys, tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text('[rig]\ntransmission_ratio = 100\n[meshing]\ncheck_torque_nm = "2,5,10"\n'
                   "check_pairs = [15, 28, 37]\n")
    record = tmp_path / "r.csv"
    record.write_text("time_s,torque_nm,input_angle_deg\n" + "".join(f"{i},{i % 7},{i}\n" for i in range(40)))
    code, _, err = run(capsys, "stiffness", record, "--rig", rig, "-o", tmp_path / "out")
    assert code == 2
    assert "rig.toml: rig constant check_torque_nm must be a list of numbers, got '2,5,10'" in err


def test_a_rig_file_with_text_in_a_list_names_the_element(tmp_path):

    rig = tmp_path / "rig.toml"
    rig.write_text('[meshing]\ncheck_torque_nm = [2, "5", 10]\ncheck_pairs = [15, 28, 37]\n')
    with pytest.raises(RigError, match=r"rig constant check_torque_nm\[1\] must be a finite number, got '5'"):
        load_rig(rig)


def _encoder_record(path, change):
    rows = [[f"{0.1 * i:.1f}", f"{(i % 20) / 4:g}", f"{i * 3}"] for i in range(40)]
    change(rows)
    path.write_text("time_s,torque_nm,input_angle_deg\n" + "".join(",".join(r) + "\n" for r in rows))
    return path


@pytest.mark.parametrize("change, message", [
    (lambda r: r[5].__setitem__(0, r[4][0]),
     r"column 'time_s' must be strictly increasing; line 7 \(t = 0\.4 s\) does not come after line 6"),
    (lambda r: r[5].__setitem__(0, "0.1"),
     r"column 'time_s' must be strictly increasing; line 7 \(t = 0\.1 s\) does not come after line 6"),
    (lambda r: r[7].__setitem__(1, "nan"), r"column 'torque_nm' has a missing, non-numeric or infinite value "
                                           r"'nan' on line 9"),
    (lambda r: r[7].__setitem__(1, "inf"), r"column 'torque_nm' has a missing, non-numeric or infinite value "
                                           r"inf on line 9"),
    (lambda r: r[7].__setitem__(1, "2.5 Nm"), r"column 'torque_nm' has a missing, non-numeric or infinite value "
                                              r"'2\.5 Nm' on line 9"),
    (lambda r: r[7].__setitem__(2, "1e150"), r"line 9: column 'input_angle_deg' must be a finite number \(its "
                                             r"magnitude is limited to 1e\+12\), got 1e\+150"),
])
def test_stiffness_record_messages_name_the_row(tmp_path, change, message):

    path = _encoder_record(tmp_path / "r.csv", change)
    with pytest.raises(RecordError, match=r"r\.csv: " + message):
        read_record(path, rig=RigConstants(transmission_ratio=100))


# -- measurements.csv: absurd magnitudes refused at read time, by row -----------------------


@pytest.mark.parametrize("column, value, shown", [
    ("angle_deg", 1e150, "1e+150"),
    ("torque_nm", 1e9, "1000000000.0"),  # made the analysis' normal matrix singular (an internal error)
])
def test_analyze_with_one_absurd_value_names_the_row(capsys, tmp_path, column, value, shown):
    table = simulate_measurements(k_u=4.33, k_l=1.44, tau_c=0.1, orientations_deg=(0,),
                                  rng=np.random.default_rng(1))
    table.loc[5, column] = value
    path = tmp_path / "measurements.csv"
    table.to_csv(path, index=False)
    code, _, err = run(capsys, "analyze", path, "-o", tmp_path / "out")
    assert code == 2
    assert f"line 7: column {column} must be a finite number in [-1e+06, 1e+06], got {shown}" in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


# -- images: size and header before reading and decoding ---------------------------------


def _chunk(kind: bytes, data: bytes) -> bytes:

    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _png(width, height, *, bits=8, colour_type=0, rows=b""):

    ihdr = struct.pack(">IIBBBBB", width, height, bits, colour_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(rows))
            + _chunk(b"IEND", b""))


def _deflate_tiff(width, height, *, bits=8):
    """A little-endian TIFF whose IFD0 declares `width` x `height` px and whose one
    strip is a small deflate stream (the decoder would inflate it to width*height bytes)."""

    data = zlib.compress(b"\0" * 1_000_000, 9)  # ~1 kB standing for a huge image
    entries = [(256, 4, 1, width), (257, 4, 1, height), (258, 3, 1, bits), (259, 3, 1, 8),
               (262, 3, 1, 1), (273, 4, 1, 8), (277, 3, 1, 1), (278, 4, 1, height), (279, 4, 1, len(data))]
    ifd_at = 8 + len(data)
    ifd = struct.pack("<H", len(entries)) + b"".join(
        struct.pack("<HHI", tag, kind, n) + (struct.pack("<HH", value, 0) if kind == 3 else struct.pack("<I", value))
        for tag, kind, n, value in entries) + struct.pack("<I", 0)
    return b"II*\x00" + struct.pack("<I", ifd_at) + data + ifd


def test_a_deflate_tiff_declaring_32000_px_is_refused_before_decoding(tmp_path):

    raw = _deflate_tiff(32000, 32000)
    assert len(raw) < 10_000 and image_size(raw, "tiff") == (32000, 32000)
    path = tmp_path / "huge.tif"
    path.write_bytes(raw)
    with pytest.raises(ImageReadError, match=r"huge\.tif: image larger than the limit \(32000x32000 px = 1024 Mpx; "
                                             r"at most 268 Mpx\)"):
        load_image(path)


def test_a_tiff_header_that_states_no_size_is_refused(tmp_path):

    path = tmp_path / "cut.tif"
    path.write_bytes(b"II*\x00" + (999_999).to_bytes(4, "little") + b"\0" * 64)
    with pytest.raises(ImageReadError, match=r"cut\.tif: corrupt TIFF header \(it does not state the image size\)"):
        load_image(path)


def test_a_sparse_3_gb_png_is_refused_before_it_is_read(tmp_path):

    path = tmp_path / "huge.png"
    path.write_bytes(_png(100, 100))
    with open(path, "r+b") as fh:
        fh.truncate(3 * 1024**3)  # sparse: no disk used, and reading it would take 3 GB
    with pytest.raises(ImageReadError, match=rf"huge\.png: 3221225472 bytes, larger than an image file may be "
                                             rf"\({MAX_IMAGE_FILE_BYTES} bytes\)") as info:
        load_image(path)
    assert info.value.reason == "too_large"


def test_a_file_that_is_no_image_is_refused_from_its_first_bytes(tmp_path):

    path = tmp_path / "notes.png"
    with open(path, "wb") as fh:
        fh.write(b"just text")
        fh.truncate(1024**3)
    with pytest.raises(ImageReadError, match=r"notes\.png: not a PNG, TIFF, BMP or JPEG image \(unrecognised"):
        read_image_bytes(path)


@pytest.mark.parametrize("size", [0, 1, 15, 16, 17, 8191, 8192, 8193, 700_001])
def test_the_bytes_read_are_the_whole_file(tmp_path, size):
    """read_image_bytes returns the file's bytes exactly, with its signature checked or
    not, whatever its size against the header and the read buffer."""
    raw = (_png(8, 8) + np.random.default_rng(size).integers(0, 256, size, np.uint8).tobytes())[:size]
    path = tmp_path / "a.png"
    path.write_bytes(raw)
    assert read_image_bytes(path, signature=False) == raw
    if size >= 16:  # a whole PNG signature (fewer bytes are refused: not an image)
        assert read_image_bytes(path) == raw


def test_the_whole_file_is_read_where_reads_return_less(tmp_path, monkeypatch):
    """A file system whose reads return a part of what was asked (a network share)
    still gives read_image_bytes the whole file."""

    class Slow(io.FileIO):
        def read(self, n=-1):
            return super().read(min(n, 1000) if n >= 0 else 1000)

    raw = _png(8, 8) + np.random.default_rng(5).integers(0, 256, 4321, np.uint8).tobytes()
    path = tmp_path / "a.png"
    path.write_bytes(raw)
    monkeypatch.setattr(images_module, "open", lambda p, mode, buffering, opener=None: Slow(p, mode), raising=False)
    assert read_image_bytes(path) == raw
    assert read_image_bytes(path, signature=False) == raw


@pytest.mark.parametrize("name, raw, message", [
    ("bw.png", _png(16, 16, bits=1, rows=b"".join(b"\x00\xaa\x55" for _ in range(16))),
     r"bw\.png: 1-bit PNG \(black and white or few grey levels\); the markers' edges are fitted to grey levels"),
    ("bw.tif", _deflate_tiff(64, 64, bits=1), r"bw\.tif: 1-bit TIFF \(black and white"),
])
def test_a_1_bit_image_is_refused_naming_the_file(tmp_path, name, raw, message):
    path = tmp_path / name
    path.write_bytes(raw)
    with pytest.raises(ImageReadError, match=message) as info:
        load_image(path)
    assert info.value.reason == "unsupported_image"


def test_one_unreadable_image_does_not_stop_a_measure_batch(capsys, tmp_path, monkeypatch):

    folder = tmp_path / "photos"
    for i, angle in enumerate((0.0, 1.0, 2.0)):
        write_image(folder / f"img_{i}.png", draw_target(angle))
    locked = folder / "img_1.png"
    real_open = open

    def refuse(path, *a, **kw):  # chmod cannot lock a file away from root: the open fails instead
        if str(path) == str(locked):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, *a, **kw)

    monkeypatch.setattr(images_module, "open", refuse, raising=False)
    code, out, err = run(capsys, "measure", folder, "--reference", folder / "img_0.png", "-o", tmp_path / "out")
    assert code == 1
    assert "2 of 3 images measured" in out
    assert "failed: " in err and "img_1.png: cannot be read (Permission denied)" in err


def test_few_open_files_degrade_process_to_threads(tmp_path):

    folder = tmp_path / "session"
    make_session(folder, orientations=(0,))

    def low_limit():
        resource.setrlimit(resource.RLIMIT_NOFILE, (16, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    done = subprocess.run([sys.executable, "-m", "vision_torsion", "process", str(folder), "-o",
                           str(tmp_path / "out"), "-j", "4"], capture_output=True, text=True, cwd=root,
                          preexec_fn=low_limit, timeout=300)
    assert done.returncode == 0, done.stderr
    assert ("WARNING: only 16 files may be open (ulimit -n), too few for 4 worker processes; measuring with 3 "
            "threads of this process instead") in done.stderr
    assert "Traceback" not in done.stderr and "internal error" not in done.stderr
