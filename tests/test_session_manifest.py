"""manifest.csv validation: one test per message, all problems in one error."""

import os

import pytest

from vision_torsion.errors import ManifestError
from vision_torsion.session import manifest as manifest_module
from vision_torsion.session.manifest import load_manifest

HEADER = "image,orientation_deg,cycle,phase,step,mass_kg"
GOOD = [
    "images/a.png,0,1,reference,0,0",
    "images/b.png,0,1,positive_unloading,0,0.04",
    "images/c.png,0,1,positive_unloading,1,0.02",
]


def write(folder, lines, *, header=HEADER, images=("a.png", "b.png", "c.png", "d.png")):
    (folder / "images").mkdir(exist_ok=True)
    for name in images:
        (folder / "images" / name).write_bytes(b"\x89PNG\r\n\x1a\n")
    path = folder / "manifest.csv"
    path.write_text("\n".join([header, *lines]) + "\n")
    return path


def test_good_manifest(tmp_path):
    m = load_manifest(write(tmp_path, GOOD + ["", "images/d.png,60,1,reference,0,0"]))
    assert [r.line for r in m.rows] == [2, 3, 4, 6]  # CSV line numbers; blank line 5 skipped
    assert m.rows[1].phase == "positive_unloading" and m.rows[1].mass_kg == 0.04
    assert m.rows[3].orientation_deg == 60.0
    assert m.image_path(m.rows[0]) == tmp_path / "images" / "a.png"


def test_extra_and_torque_columns(tmp_path):
    m = load_manifest(write(tmp_path, ["images/a.png,0,1,reference,0,0,,,note",
                                       "images/b.png,0,1,positive_loading,1,,0.05,0.001,x"],
                            header=HEADER + ",torque_nm,torque_std_nm,notes"))
    assert m.rows[1].mass_kg is None
    assert (m.rows[1].torque_nm, m.rows[1].torque_std_nm) == (0.05, 0.001)
    assert dict(m.rows[0].fields)["notes"] == "note"


def one_row(tmp_path, row, **kw):
    return write(tmp_path, [GOOD[0], row], **kw)


@pytest.mark.parametrize(
    "row, message",
    [
        ("images/b.png,0,1,positive_loading,1", r"line 3: 5 fields; expected 6"),
        (",0,1,positive_loading,1,0.02", r"line 3: image is empty"),
        ("/etc/passwd.png,0,1,positive_loading,1,0.02", r"line 3: image '/etc/passwd\.png' is an absolute path"),
        ("../b.png,0,1,positive_loading,1,0.02", r"line 3: image '\.\./b\.png' leaves the session folder \('\.\.'\)"),
        (
            "images/../../b.png,0,1,positive_loading,1,0.02",
            r"line 3: image 'images/\.\./\.\./b\.png' leaves the session folder",
        ),
        ("images/b.txt,0,1,positive_loading,1,0.02", r"line 3: image 'images/b\.txt' is not an image file name"),
        ("images/zz.png,0,1,positive_loading,1,0.02", r"line 3: image 'images/zz\.png': no such file"),
        ("images/b.png,north,1,positive_loading,1,0.02", r"line 3: orientation_deg 'north' is not a number"),
        ("images/b.png,0,0,positive_loading,1,0.02", r"line 3: cycle '0' is not a whole number >= 1"),
        ("images/b.png,0,1,positive_loading,1.5,0.02", r"line 3: step '1\.5' is not a whole number >= 0"),
        (
            "images/b.png,0,1,sideways,1,0.02",
            r"line 3: phase 'sideways' is unknown; expected one of reference, positive_unloading",
        ),
        (
            "images/b.png,0,1,positive_loading,1,20g",
            r"line 3: mass_kg '20g' is not a number; expected the mass on each pan in kg",
        ),
        ("images/b.png,0,1,positive_loading,1,nan", r"line 3: mass_kg 'nan' is not a number"),
        ("images/b.png,0,1,positive_loading,1,-0.02", r"line 3: mass_kg '-0\.02' is negative"),
        ("images/b.png,0,1,positive_loading,1,", r"line 3: mass_kg '' is not a number"),
        (
            "images/b.png,60,1,reference,0,0.02",
            r"line 3: mass_kg '0\.02' on a reference row; a reference image is taken at zero load",
        ),
        (
            "images/a.png,0,1,positive_loading,1,0.02",
            r"line 3: duplicate row: image 'images/a\.png' is already listed on line 2",
        ),
        (
            "images/b.png,0,1,reference,0,0",
            r"line 3: duplicate row: orientation 0, cycle 1, reference, step 0 is already on line 2",
        ),
        ("images/b.png,0,2,reference,0,0", r"line 3: second reference row of orientation 0 \(the first is on line 2\)"),
    ],
)
def test_row_messages(tmp_path, row, message):
    with pytest.raises(ManifestError, match=message):
        load_manifest(one_row(tmp_path, row))


@pytest.mark.parametrize(
    "row, message",
    [
        ("images/b.png,0,1,positive_loading,1,,abc,0.001", r"line 3: torque_nm 'abc' is not a number"),
        ("images/b.png,0,1,positive_loading,1,,0.05,", r"line 3: torque_nm is given without torque_std_nm"),
        ("images/b.png,0,1,positive_loading,1,,0.05,-1", r"line 3: torque_std_nm '-1' is negative"),
    ],
)
def test_torque_column_messages(tmp_path, row, message):
    path = write(tmp_path, ["images/a.png,0,1,reference,0,0,,", row], header=HEADER + ",torque_nm,torque_std_nm")
    with pytest.raises(ManifestError, match=message):
        load_manifest(path)


def test_steps_out_of_order(tmp_path):
    path = write(tmp_path, [GOOD[0], GOOD[2], GOOD[1]])
    with pytest.raises(
        ManifestError,
        match=r"line 4: steps out of order: orientation 0, "
        r"cycle 1, positive_unloading, step 0 comes after step 1 \(line 3\)",
    ):
        load_manifest(path)


def test_symlink_leaving_the_folder(tmp_path):
    outside = tmp_path / "outside.png"
    outside.write_bytes(b"\x89PNG\r\n\x1a\n")
    session = tmp_path / "session"
    session.mkdir()
    path = write(session, [GOOD[0], "images/link.png,0,1,positive_loading,1,0.02"])
    os.symlink(outside, session / "images" / "link.png")
    with pytest.raises(
        ManifestError,
        match=r"line 3: image 'images/link\.png' leaves the "
        r"session folder \(through a symbolic link\)",
    ):
        load_manifest(path)


def test_symlink_inside_the_folder_is_fine(tmp_path):
    path = write(tmp_path, [GOOD[0], "images/link.png,0,1,positive_loading,1,0.02"])
    os.symlink(tmp_path / "images" / "b.png", tmp_path / "images" / "link.png")
    assert len(load_manifest(path).rows) == 2


def test_folder_instead_of_file(tmp_path):
    path = one_row(tmp_path, "images/dir.png,0,1,positive_loading,1,0.02")
    (tmp_path / "images" / "dir.png").mkdir()
    with pytest.raises(ManifestError, match=r"line 3: image 'images/dir\.png' is not a regular file"):
        load_manifest(path)


def test_unreadable_file(tmp_path, monkeypatch):
    # chmod cannot make a file unreadable for root, so the open itself is made to fail.
    def refuse(path, mode="r", *a, **kw):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(manifest_module, "open", refuse, raising=False)
    with pytest.raises(
        ManifestError,
        match=r"line 2: image 'images/a\.png' cannot be read "
        r"\(Permission denied\)",
    ):
        load_manifest(write(tmp_path, GOOD[:1]))


def test_check_files_off_skips_the_file_checks(tmp_path):
    path = one_row(tmp_path, "images/zz.png,0,1,positive_loading,1,0.02")
    assert len(load_manifest(path, check_files=False).rows) == 2


@pytest.mark.parametrize(
    "text, message",
    [
        ("", r"manifest\.csv: empty file; expected the header line image,orientation_deg"),
        ("image,cycle,phase,step,mass_kg\n", r"line 1: missing column\(s\) orientation_deg"),
        (HEADER + ",step\n", r"line 1: repeated column\(s\) step"),
        (HEADER + "\n", r"no image rows below the header"),
    ],
)
def test_file_level_messages(tmp_path, text, message):
    (tmp_path / "manifest.csv").write_text(text)
    with pytest.raises(ManifestError, match=message):
        load_manifest(tmp_path / "manifest.csv")


def test_missing_manifest(tmp_path):
    with pytest.raises(ManifestError, match=r"manifest\.csv: no such file"):
        load_manifest(tmp_path / "manifest.csv")


def test_all_problems_in_one_message(tmp_path):
    path = write(
        tmp_path,
        [
            GOOD[0],
            "images/zz.png,0,1,sideways,1,abc",
            "images/c.png,0,1,positive_loading,1,0.02",
            "images/c.png,0,1,positive_loading,2,0.04",
        ],
    )
    with pytest.raises(ManifestError) as info:
        load_manifest(path)
    text = str(info.value)
    assert "4 problem(s) (line numbers are CSV lines, the header is line 1)" in text
    for fragment in (
        "line 3: image 'images/zz.png': no such file",
        "line 3: phase 'sideways' is unknown",
        "line 3: mass_kg 'abc' is not a number",
        "line 5: duplicate row: image 'images/c.png' is already listed on line 4",
    ):
        assert fragment in text
