"""`vision-torsion measure --target`: a folder of images of an N-marker target, each with
its status, the dots dropped, the axis shift and whether the camera was bumped."""

import dataclasses

import cv2
import numpy as np
import pandas as pd
import pytest

from vision_torsion.cli import main
from vision_torsion.errors import TargetError
from vision_torsion.rigid import TARGET_COLUMNS, measure_target_folder
from vision_torsion.synthetic import Scene, render, target_scene
from vision_torsion.synthetic.geometry import marker_centres_image

SCENE = target_scene("ring16", px_per_mm=7.5,
                     base=Scene().replace(disk=dataclasses.replace(Scene().disk, center_x=700.37, center_y=500.61)))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("ring16")
    images = root / "images"
    images.mkdir()
    cv2.imwrite(str(root / "reference.png"), render(SCENE, 0.0, seed=1).image.astype(np.uint8))
    cv2.imwrite(str(images / "img_1.png"), render(SCENE, 100.0, seed=2).image.astype(np.uint8))
    cv2.imwrite(str(images / "img_2.png"), render(SCENE, 200.0, seed=3).image.astype(np.uint8))
    bumped = SCENE.replace(disk=dataclasses.replace(SCENE.disk, center_y=SCENE.disk.center_y + 1.0))
    cv2.imwrite(str(images / "img_3.png"), render(bumped, 200.0, seed=4).image.astype(np.uint8))
    hidden = render(SCENE, 210.0, seed=5).image.astype(np.float64)
    x, y = marker_centres_image(SCENE, 210.0)[0]
    yy, xx = np.mgrid[0:hidden.shape[0], 0:hidden.shape[1]]
    hidden[np.hypot(xx - x, yy - y) < 50] = SCENE.disk.background_level
    cv2.imwrite(str(images / "img_4.png"), hidden.astype(np.uint8))
    (images / "img_5.png").write_bytes(b"not a png")
    return root


def test_folder_of_a_ring_target(folder, tmp_path):
    res = measure_target_folder(folder / "images", reference=folder / "reference.png", target="ring16",
                                out_dir=tmp_path / "out")
    t = res.table
    assert list(t.columns) == TARGET_COLUMNS and list(t["image"]) == [f"img_{k}.png" for k in range(1, 6)]
    assert list(t["status"]) == ["ok", "ok", "ok", "ambiguous", "failed"]
    # unwrapped along the names; 0.002° is > 10 CRLB of ring16 (1.5e-4°)
    assert t["angle_deg"][:3].to_numpy() == pytest.approx([100.0, 200.0, 200.0], abs=0.002)
    assert list(t["bump"]) == [False, False, True, False, False]
    assert t["shift_y_px"][2] == pytest.approx(1.0, abs=0.02) and "not a rotation" in t["message"][2]
    assert "index mark (dot 0)" in t["message"][3] and np.isnan(t["angle_deg"][3])
    assert "img_5.png" in t["message"][4]
    assert res.n_ok == 3 and res.n_failed == 2
    assert pd.read_csv(res.path)["status"].tolist() == list(t["status"])


def test_command_reports_the_bump_and_fails_on_the_rest(folder, tmp_path, capsys):
    code = main(["measure", str(folder / "images"), "--reference", str(folder / "reference.png"),
                 "--target", "ring16", "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 1
    assert "img_3.png: img_3.png: the shaft axis moved by" in err
    assert "ambiguous: img_4.png: the index mark (dot 0)" in err and "img_5.png" in err


def test_reference_of_another_layout_is_refused(folder, tmp_path):
    with pytest.raises(TargetError, match=r"reference: no two markers have the sizes and spacing of two dots "
                                          r"of the target 'grid5'") as e:
        measure_target_folder(folder / "images", reference=folder / "reference.png", target="grid5",
                              out_dir=tmp_path / "out")
    assert e.value.reason == "layout_mismatch" and not (tmp_path / "out" / "angles.csv").exists()
