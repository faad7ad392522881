"""See what was detected: the overlay helper, measure --overlay, the report section."""

import numpy as np
import pytest
from helpers import draw_target, make_session

from vision_torsion.cli import main
from vision_torsion.errors import OutputError
from vision_torsion.fileio import RECORD_NAME
from vision_torsion.images import write_image
from vision_torsion.overlay import annotate, detections, overlay_image, write_overlays


def test_overlay_draws_the_fitted_circles_where_the_markers_are():
    img = draw_target(20.0)
    table, pair, why = detections(img)
    assert pair is not None and why == ""
    rgb = overlay_image(img)
    assert rgb.shape == img.shape + (3,) and rgb.dtype == np.uint8
    grey = np.repeat(img[:, :, None], 3, axis=2)
    changed = np.any(rgb != grey, axis=2)
    ys, xs = np.nonzero(changed)
    for m in (pair.first, pair.second):
        # the drawn circle passes through the fitted radius around the fitted centre
        # (within the 2-px line of the pair plus anti-aliasing: 3 px)
        d = np.hypot(xs - m.x_px, ys - m.y_px)
        ring = np.abs(d - m.radius_px) < 3
        assert ring.sum() > 2 * np.pi * m.radius_px
    assert np.array_equal(img, draw_target(20.0))  # the input is not modified


def test_no_pair_is_said_on_the_image():
    blank = np.full((150, 200), 220, np.uint8)
    _, pair, why = detections(blank)
    assert pair is None and "found 0 usable marker(s)" in why
    assert np.any(overlay_image(blank) != 220)  # the message is drawn


def test_annotate_returns_an_axes():
    ax = annotate(draw_target(5.0), name="x.png")
    assert ax.get_title().startswith("x.png: detected markers")


def test_overlay_folder_cannot_be_an_input(tmp_path):
    write_image(tmp_path / "a.png", draw_target(0.0))
    with pytest.raises(OutputError, match="the overlay folder cannot be an input folder"):
        write_overlays([tmp_path / "a.png"], tmp_path, inputs=[tmp_path])


def test_measure_overlay_option(tmp_path, capsys):
    imgs = tmp_path / "imgs"
    for k, angle in enumerate((0.0, 3.0, 7.0)):
        write_image(imgs / f"img_{k}.png", draw_target(angle))
    assert main(["measure", str(imgs), "--reference", str(imgs / "img_0.png"),
                 "--overlay", str(tmp_path / "ov")]) == 0
    assert sorted(p.name for p in (tmp_path / "ov").iterdir()) == [
        RECORD_NAME, "img_0_overlay.png", "img_1_overlay.png", "img_2_overlay.png"]
    assert "wrote 3 overlay(s)" in capsys.readouterr().out


def test_report_shows_each_reference_with_its_detections(tmp_path):
    from vision_torsion.report.session_report import report_session

    make_session(tmp_path / "s", orientations=(0, 60))
    page = report_session(tmp_path / "s", jobs=1).files.report_html.read_text()
    assert "Detected markers on the reference images" in page
    for o in ("0°: images/o000", "60°: images/o060"):
        assert f'<img alt="orientation {o}_c1_01_reference_s00.png" src="data:image/jpeg;base64,' in page
