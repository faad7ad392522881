"""process_session bookkeeping, with a stand-in measurement core (helpers.FakeCore, passed in
as process_session's ``measure`` function).

These tests check what process owns: validation first, the output table, failure
isolation, the cache and resumability, atomic writes, never writing into the
session folder. The real measurement core is exercised in test_session_core.py.
"""

import argparse
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from helpers import FakeCore, draw_target, make_session, tree_digest

from vision_torsion import fileio
from vision_torsion.cli import process as process_cli
from vision_torsion.errors import ManifestError, OutputError, SessionError
from vision_torsion.images import write_image
from vision_torsion.session import process as process_module
from vision_torsion.session import process_session
from vision_torsion.session.cache import CACHE_DIRNAME, count_entries
from vision_torsion.session.process import OUTPUT_COLUMNS

# The stand-in's darkness-weighted centroids of OpenCV's anti-aliased discs are off
# by up to 0.033° in direction (measured over -30°..30°); an angle is a difference
# of two directions, so up to 0.066°.
ANGLE_TOL_DEG = 0.07


@pytest.fixture
def core():
    return FakeCore()


@pytest.fixture
def session(tmp_path):
    folder = tmp_path / "session"
    plan, truth = make_session(folder)
    return folder, plan, truth


def read(path):
    return pd.read_csv(path, keep_default_na=False, dtype={"message": str})


def test_table_torque_and_angles(session, core):
    folder, plan, truth = session
    result = process_session(folder, jobs=1, measure=core.measure_pair)
    assert result.ok and result.n_images == len(plan.rows) == 20
    assert (result.n_measured, result.n_cached) == (20, 0)
    table = read(result.measurements_path)
    assert list(table.columns) == ["image", "orientation_deg", "cycle", "phase", "step",
                                   "mass_kg", *OUTPUT_COLUMNS]
    assert list(table["image"]) == [r["image"] for r in plan.rows]
    assert set(table["status"]) == {"ok"} and set(table["torque_source"]) == {"weights"}
    # torque: sign from the phase, 2 m g r
    sign = table["phase"].map(lambda p: {"pos": 1, "neg": -1, "ref": 0}[p[:3]])
    expected = sign * 2 * table["mass_kg"] * 9.81 * 0.05
    assert (table["torque_nm"] - expected).abs().max() < 1e-15
    # no friction term in this rig: only loaded images carry the mass tolerance
    loaded = table["mass_kg"] > 0
    assert (table["torque_std_nm"][loaded] > 0).all()
    assert (table["torque_std_nm"][~loaded] == 0).all()
    # angles relative to each orientation's reference row
    for o, group in table.groupby("orientation_deg"):
        ref = truth[group["image"].iloc[0]]
        for image, angle in zip(group["image"], group["angle_deg"]):
            assert angle == pytest.approx(truth[image] - ref, abs=ANGLE_TOL_DEG)


def test_angle_sign(tmp_path, core):
    _, truth = make_session(tmp_path / "s", orientations=(0,), angle_sign=-1)
    table = read(process_session(tmp_path / "s", jobs=1, measure=core.measure_pair).measurements_path)
    ref, top = table.iloc[0], table[table["phase"] == "positive_unloading"].iloc[0]
    assert top["torque_nm"] > 0 and top["angle_deg"] < 0
    assert top["angle_deg"] == pytest.approx(-(truth[top["image"]] - truth[ref["image"]]),
                                             abs=ANGLE_TOL_DEG)


@pytest.mark.parametrize("jobs", [1, 3])  # measured here; read by three threads
def test_one_bad_image_does_not_stop_the_run(session, core, jobs):
    folder, plan, _ = session
    bad = plan.rows[3]["image"]
    (folder / bad).write_bytes(b"this is not a png")
    result = process_session(folder, jobs=jobs, measure=core.measure_pair)
    assert not result.ok and (result.n_ok, result.n_failed) == (19, 1)
    table = read(result.measurements_path)
    row = table[table["image"] == bad].iloc[0]
    assert row["status"] == "failed"
    assert row["message"] == f"{bad}: not a PNG, TIFF, BMP or JPEG image (unrecognised file header)"
    assert row["angle_deg"] == "" and row["torque_nm"] != ""  # torque is known regardless
    assert result.failures == ((bad, row["message"]),)


@pytest.mark.parametrize("jobs", [1, 3])
def test_failed_reference_fails_its_orientation_only(session, core, jobs):
    folder, plan, _ = session
    ref = plan.rows[0]["image"]
    write_image(folder / ref, np.full((150, 200), 220.0))  # markers missing
    result = process_session(folder, jobs=jobs, measure=core.measure_pair)
    table = read(result.measurements_path)
    o0 = table[table["orientation_deg"] == 0]
    assert (o0["status"] == "failed").all() and result.n_failed == len(o0) == 10
    assert o0["message"].iloc[0] == f"{ref}: found 0 marker(s), expected 2"
    assert o0["message"].iloc[1] == (f"reference image {ref} (line 2) of orientation 0 "
                                     "failed, so no angle can be measured")
    assert (table[table["orientation_deg"] == 60]["status"] == "ok").all()


def test_cli_exit_status(session, core, capsys):
    folder, plan, _ = session
    p = argparse.ArgumentParser()
    process_cli.register(p.add_subparsers())
    args = p.parse_args(["process", str(folder), "--jobs", "1", "--quiet"])
    assert args.func(args) == 0
    (folder / plan.rows[5]["image"]).write_bytes(b"")
    assert args.func(args) == 1
    assert f"failed: {plan.rows[5]['image']}: " in capsys.readouterr().err


def test_cli_help(capsys):
    p = argparse.ArgumentParser()
    process_cli.register(p.add_subparsers())
    with pytest.raises(SystemExit) as info:
        p.parse_args(["process", "--help"])
    assert info.value.code == 0 and "--jobs N" in capsys.readouterr().out


def test_validation_happens_before_measuring(session, core):
    folder, plan, _ = session
    (folder / plan.rows[7]["image"]).unlink()
    (folder / plan.rows[7]["image"]).mkdir()  # not a file: a problem (a missing one is pending)
    with pytest.raises(ManifestError, match=r"line 9: image '.*' is not a regular file"):
        process_session(folder, jobs=1, measure=core.measure_pair)
    assert core.measured == [] and not (folder / "results").exists()


def test_output_folder_cannot_be_the_session_folder(session, core):
    with pytest.raises(SessionError, match="cannot be the session folder itself"):
        process_session(session[0], out_dir=session[0], jobs=1, measure=core.measure_pair)


def test_session_folder_is_never_modified(session, core, tmp_path):
    folder, plan, _ = session
    (folder / plan.rows[4]["image"]).write_bytes(b"garbage")  # a failure is written too
    before = tree_digest(folder)
    process_session(folder, out_dir=tmp_path / "elsewhere", jobs=1, measure=core.measure_pair)
    assert tree_digest(folder) == before
    process_session(folder, jobs=1, measure=core.measure_pair)  # default output: only results/ appears
    assert tree_digest(folder, exclude=("results",)) == before
    assert (folder / "results" / "measurements.csv").is_file()


@pytest.mark.parametrize("jobs", [1, 3])  # with threads reading ahead, the same
def test_resume_after_interruption_gives_the_same_file(session, tmp_path, jobs):
    folder, plan, _ = session
    (folder / plan.rows[4]["image"]).write_bytes(b"garbage")  # failures are cached too
    full = FakeCore()
    reference = process_session(folder, out_dir=tmp_path / "a", jobs=1, measure=full.measure_pair).measurements_path
    # interrupted run: Ctrl-C after 8 measured images (rows 0-8, the garbage row 4
    # failing on the way), nothing written but the cache
    with pytest.raises(KeyboardInterrupt):
        process_session(folder, out_dir=tmp_path / "b", jobs=jobs,
                        measure=FakeCore(interrupt_after=8).measure_pair)
    assert not (tmp_path / "b" / "measurements.csv").exists()
    assert count_entries(tmp_path / "b" / CACHE_DIRNAME) == 8 + 1  # + the failure
    resumed = FakeCore()
    result = process_session(folder, out_dir=tmp_path / "b", jobs=jobs, measure=resumed.measure_pair)
    assert (result.n_measured, result.n_cached) == (20 - 9, 9)
    assert len(resumed.measured) == 11 and len(full.measured) == 19
    assert result.measurements_path.read_bytes() == reference.read_bytes()


@pytest.mark.parametrize("jobs", [1, 3])
def test_an_image_removed_after_validation_fails_alone(session, core, monkeypatch, jobs):
    folder, plan, _ = session
    gone = plan.rows[5]["image"]
    load = process_module.load_session

    def load_then_remove(path, **kw):
        loaded = load(path, **kw)
        (folder / gone).unlink()
        return loaded

    monkeypatch.setattr(process_module, "load_session", load_then_remove)
    result = process_session(folder, jobs=jobs, measure=core.measure_pair)
    assert (result.n_ok, result.n_failed) == (19, 1)
    row = read(result.measurements_path).set_index("image").loc[gone]
    assert row["message"] == f"{gone}: no such file"
    assert count_entries(folder / "results" / CACHE_DIRNAME) == 19  # not cached: tried again next run


@pytest.mark.parametrize("jobs", [1, 3])
def test_an_unexpected_error_fails_its_image_and_is_not_cached(session, core, jobs):
    folder, plan, _ = session
    broken = plan.rows[6]["image"]

    def measure_pair(image, *, settings, name=None, candidates=None):
        if name.endswith(broken):
            raise RuntimeError("a bug")
        return core.measure_pair(image, settings=settings, name=name)

    result = process_session(folder, jobs=jobs, measure=measure_pair)
    assert result.failures == ((broken, "internal error: RuntimeError: a bug"),)
    assert count_entries(folder / "results" / CACHE_DIRNAME) == 19


def test_rerun_measures_only_new_or_changed_images(session, core, tmp_path):
    folder, plan, truth = session
    process_session(folder, jobs=1, measure=core.measure_pair)
    assert process_session(folder, jobs=1, measure=core.measure_pair).n_measured == 0
    # a replaced image is measured again, and only it
    write_image(folder / plan.rows[6]["image"], draw_target(truth[plan.rows[6]["image"]] + 1))
    result = process_session(folder, jobs=1, measure=core.measure_pair)
    assert (result.n_measured, result.n_cached) == (1, 19)
    # images added to the manifest
    make_session(tmp_path / "bigger", orientations=(0, 60, 120))
    (folder / "manifest.csv").write_text((tmp_path / "bigger" / "manifest.csv").read_text())
    for image in (tmp_path / "bigger" / "images").iterdir():
        if image.name.startswith("o120"):
            (folder / "images" / image.name).write_bytes(image.read_bytes())
    core.measured.clear()
    result = process_session(folder, jobs=1, measure=core.measure_pair)
    assert (result.n_measured, result.n_cached) == (10, 20)
    assert all("o120" in m for m in core.measured)


def test_changed_settings_measure_everything_again(session, core):
    folder, _, _ = session
    process_session(folder, jobs=1, measure=core.measure_pair)
    toml = folder / "session.toml"
    toml.write_text(toml.read_text().replace('[markers]\n', '[markers]\nradius_range = [4.0, 30.0]\n'))
    assert process_session(folder, jobs=1, measure=core.measure_pair).n_measured == 20


def test_changed_measuring_code_measures_everything_again(session, core, monkeypatch):
    from vision_torsion.session import process as process_module

    folder, _, _ = session
    process_session(folder, jobs=1, measure=core.measure_pair)
    monkeypatch.setattr(process_module, "code_fingerprint", lambda: "another core")
    assert process_session(folder, jobs=1, measure=core.measure_pair).n_measured == 20
    assert process_session(folder, jobs=1, measure=core.measure_pair).n_measured == 0


def test_results_are_written_atomically(session, core, monkeypatch):
    folder, plan, _ = session
    first = process_session(folder, jobs=1, measure=core.measure_pair).measurements_path
    before = first.read_bytes()
    (folder / plan.rows[2]["image"]).write_bytes(b"garbage")  # the new table would differ

    def fail(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(fileio.os, "replace", fail)
    with pytest.raises(OutputError, match=r"measurements\.csv: cannot write \(no space left on the device\)"):
        process_session(folder, jobs=1, measure=core.measure_pair)
    assert first.read_bytes() == before
    assert [p.name for p in first.parent.iterdir() if p.name.endswith(".tmp")] == []


def test_measured_torque_overrides_the_weights(tmp_path, core):
    folder = tmp_path / "s"
    make_session(folder, orientations=(0,))
    manifest = folder / "manifest.csv"
    lines = manifest.read_text().splitlines()
    lines[0] += ",torque_nm,torque_std_nm"
    lines[1] += ",,"
    lines[2] += ",0.0801,0.0004"
    lines[3:] = [line + ",," for line in lines[3:]]
    manifest.write_text("\n".join(lines) + "\n")
    table = read(process_session(folder, jobs=1, measure=core.measure_pair).measurements_path)
    assert list(table.columns).count("torque_nm") == 1
    assert (table["torque_nm"][1], table["torque_std_nm"][1]) == (0.0801, 0.0004)
    assert table["torque_source"][1] == "measured" and table["torque_source"][2] == "weights"


def _set_correction(folder, name):
    """Point the session's [markers] correction at `name` (relative to the folder)."""
    toml = folder / "session.toml"
    text = toml.read_text()
    assert "[markers]" in text
    toml.write_text(text.replace("[markers]", f'[markers]\ncorrection = "{name}"', 1))


def test_plane_correction_is_applied_to_the_angles(session, core):
    """A correction that stretches x by 1.5 turns a direction a (from the x axis) into
    atan2(sin a, 1.5 cos a); the angles are differences of such directions."""
    from vision_torsion.correction import PlaneCorrection

    folder, plan, truth = session
    PlaneCorrection(homography=np.diag([1.5, 1.0, 1.0])).save(folder / "plane.toml")
    _set_correction(folder, "plane.toml")
    table = read(process_session(folder, jobs=1, measure=core.measure_pair).measurements_path)

    def seen(angle_deg):
        a = np.radians(angle_deg)
        return np.degrees(np.arctan2(np.sin(a), 1.5 * np.cos(a)))

    moved = 0
    for _, group in table.groupby("orientation_deg"):
        ref = truth[group["image"].iloc[0]]
        for image, angle in zip(group["image"], group["angle_deg"]):
            expected = seen(truth[image]) - seen(ref)
            assert angle == pytest.approx(expected, abs=ANGLE_TOL_DEG)
            moved += abs(expected - (truth[image] - ref)) > 2 * ANGLE_TOL_DEG  # not the uncorrected angle
    assert moved >= 4


def test_bad_correction_file_fails_before_measuring(session, core):
    from vision_torsion.errors import CalibrationError

    folder, _, _ = session
    (folder / "plane.toml").write_text("not a correction")
    _set_correction(folder, "plane.toml")
    with pytest.raises(CalibrationError, match="plane.toml"):
        process_session(folder, jobs=1, measure=core.measure_pair)
    assert core.measured == []


_FAULTS_OF_REALLOCATION = r"""
import resource, sys
import numpy as np
from vision_torsion.session.worker import reuse_freed_memory
if sys.argv[1] == "reuse":
    assert reuse_freed_memory()
def faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
import cv2
rng = np.random.default_rng(1)
png = cv2.imencode(".png", rng.integers(0, 8, (1000, 1400), dtype=np.uint8))[1].tobytes()
def read():  # as a session's reader: the file's bytes, then the image decoded from them
    return cv2.imdecode(np.frombuffer(bytes(png), np.uint8), cv2.IMREAD_UNCHANGED)
read()
before = faults()
for _ in range(20):
    read()
print(faults() - before)
"""


def _glibc() -> bool:
    try:
        return bool(os.confstr("CS_GNU_LIBC_VERSION"))
    except (AttributeError, ValueError, OSError):
        return False


@pytest.mark.skipif(not _glibc(), reason="glibc's allocator only")
def test_reuse_freed_memory_keeps_an_images_blocks_for_the_next():
    # glibc's default maps an image's large blocks afresh for every image and faults
    # on every page of them (~340 for a decoded 1400 x 1000 image alone); kept for
    # reuse, the blocks of one image serve the next. Counted in fresh processes: the
    # setting is process-wide and not undone.
    def faults(mode):
        out = subprocess.run([sys.executable, "-c", _FAULTS_OF_REALLOCATION, mode], check=True,
                             capture_output=True, text=True)
        return int(out.stdout)

    if faults("default") < 20 * 340 / 2:  # e.g. transparent huge pages always on: few faults anyway
        pytest.skip("this system's allocator and kernel do not fault on every page of each image")
    assert faults("reuse") < 20 * 340 / 20


def test_saturated_fraction_counts_pixels_at_full_scale():
    """The fraction of pixels at the image's full scale, whatever the bit depth; an image
    whose maximum is below full scale is exactly 0 (decided by its maximum alone)."""
    from vision_torsion.images import GreyImage
    from vision_torsion.session.worker import saturated_fraction

    rng = np.random.default_rng(30)
    eight = rng.integers(0, 255, size=(40, 50), dtype=np.uint8)  # 0..254: nothing at 255
    assert saturated_fraction(GreyImage(eight, "a.png", 8)) == 0.0
    eight[3, 4] = eight[7, 1] = eight[39, 49] = 255
    assert saturated_fraction(GreyImage(eight, "a.png", 8)) == 3 / eight.size
    twelve = rng.integers(0, 4095, size=(30, 20), dtype=np.uint16)
    assert saturated_fraction(GreyImage(twelve, "b.png", 12)) == 0.0
    twelve[0, 0] = 4095
    assert saturated_fraction(GreyImage(twelve, "b.png", 12)) == 1 / twelve.size
    assert saturated_fraction(GreyImage(np.full((8, 8), 255.0, np.float32), "c.png", 8)) == 1.0
