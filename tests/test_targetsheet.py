"""The printable target: a vector PDF at true scale, checked by printing it to pixels at a
known resolution and measuring the dots with the package's own detector."""

import shutil
import subprocess

import numpy as np
import pytest

from vision_torsion.cli import main
from vision_torsion.errors import OutputError, TargetError
from vision_torsion.images import load_image
from vision_torsion.markers import find_markers
from vision_torsion.rigid import identify_markers
from vision_torsion.targets import load_target, ring_dot_diameter_mm, ring_target
from vision_torsion.targetsheet import parse_length_mm, write_target_pdf


def test_page_is_a4_in_points(tmp_path):
    raw = write_target_pdf(tmp_path / "t.pdf", "ring16").read_bytes()
    assert raw.startswith(b"%PDF-") and b"/MediaBox [ 0 0 595.2755905512 841.8897637795 ]" in raw


@pytest.mark.skipif(shutil.which("pdftoppm") is None, reason="needs poppler's pdftoppm to rasterise the PDF")
def test_dots_are_at_true_scale(tmp_path):
    # 200 dpi: 7.874 px per mm; the ring's scale from 16 fitted centres is good to ~1e-4
    pdf = write_target_pdf(tmp_path / "t.pdf", "ring16")
    subprocess.run(["pdftoppm", "-r", "200", "-gray", "-png", "-singlefile", str(pdf), str(tmp_path / "t")],
                   check=True)
    table = find_markers(load_image(tmp_path / "t.png"))
    ident = identify_markers(table, load_target("ring16"))
    assert ident.status == "ok"
    assert ident.scale_px_per_mm == pytest.approx(200 / 25.4, rel=2e-3)
    radii = table.loc[list(ident.rows), "radius_px"].to_numpy()
    np.testing.assert_allclose(radii, np.array([6.0] + [4.8] * 15) * 200 / 25.4, rtol=0.02)


def test_existing_file_is_refused_without_overwrite(tmp_path):
    out = tmp_path / "t.pdf"
    out.write_bytes(b"mine")
    with pytest.raises(OutputError, match=r"t.pdf: already exists; choose another name or overwrite") as err:
        write_target_pdf(out, "ring8")
    assert err.value.reason == "exists" and out.read_bytes() == b"mine"


def test_target_too_large_for_the_page(tmp_path):
    with pytest.raises(TargetError, match=r"does not fit the a4 page \(210 x 297 mm\)") as err:
        write_target_pdf(tmp_path / "t.pdf", ring_target(16, diameter_mm=250, dot_diameter_mm=20,
                                                          index_diameter_mm=26), page="A4")
    assert err.value.reason == "too_large" and not (tmp_path / "t.pdf").exists()


def test_unknown_page():
    with pytest.raises(TargetError, match=r"page must be one of a4, a3, letter, got 'b5'"):
        write_target_pdf("unused.pdf", "ring16", page="b5")


@pytest.mark.parametrize("text, mm", [("80mm", 80.0), ("8 cm", 80.0), ("1in", 25.4), ("12.5", 12.5)])
def test_lengths(text, mm):
    assert parse_length_mm(text, name="--diameter") == pytest.approx(mm)


def test_bad_length_names_the_option():
    with pytest.raises(TargetError, match=r"--pitch must be a positive length such as 80mm, 8cm or 3in, got '-3mm'"):
        parse_length_mm("-3mm", name="--pitch")


def test_ring_dots_leave_a_gap_of_one_radius_beside_the_index():
    for n in (4, 8, 16, 24, 40):
        d = ring_dot_diameter_mm(n, 80.0)
        chord = 80.0 * np.sin(np.pi / n)
        assert chord - 1.25 * d / 2 - d / 2 >= d / 2 - 1e-9 and d <= 0.12 * 80.0 + 1e-12


def test_command_writes_the_pdf_and_the_table(tmp_path, capsys):
    out = tmp_path / "ring.pdf"
    assert main(["target", str(out), "--layout", "ring", "--markers", "16", "--diameter", "80mm"]) == 0
    text = capsys.readouterr().out
    assert out.read_bytes().startswith(b"%PDF-")
    assert 'layout = "ring"\nmarkers = 16\ndiameter_mm = 80.0\ndot_diameter_mm = 9.6\nindex_diameter_mm = 12.0' in text
    assert main(["target", str(out), "--layout", "ring"]) == 2  # exists, no --force
    assert "already exists" in capsys.readouterr().err


def test_command_warns_of_a_symmetric_target(tmp_path, capsys):
    assert main(["target", str(tmp_path / "g.pdf"), "--layout", "grid", "--rows", "4", "--columns", "4",
                 "--no-index"]) == 0
    assert "maps onto itself under turns of 90°" in capsys.readouterr().out


def test_command_takes_a_ready_target(tmp_path, capsys):
    assert main(["target", str(tmp_path / "g.pdf"), "--target", "grid5"]) == 0
    assert "'grid5', 25 dots (grid)" in capsys.readouterr().out
