"""Watch and bind that cannot drift: one result per cache key whichever command
measures first, and a vanished camera folder is an error naming it."""

import shutil

import pytest

from vision_torsion.cli import main
from vision_torsion.errors import SessionError
from vision_torsion.session import process_session
from vision_torsion.session.bind import bind_session
from vision_torsion.synthetic import Scene
from vision_torsion.synthetic.scene import DiskSpec, ImageSpec, MarkerSpec
from vision_torsion.synthetic.scripted_camera import ScriptedCamera, capture_script
from vision_torsion.synthetic.session import SessionSpec

# 480×360 with 16 px markers: large enough for measure_pair's coarse first look
# (the candidates process finds ahead of measuring), where bind's own candidate
# search once gave angles ~1e-4° apart from process's for the same bytes
SCENE = Scene(image=ImageSpec(480, 360), disk=DiskSpec(center_x=240.3, center_y=180.4, background_level=200.0),
              markers=MarkerSpec(radius_px=16.0, distance_px=150.0, positions_deg=(10.0, 190.0)), name="mid")
SPEC = SessionSpec(max_torque_nm=0.07848, orientations_deg=(0.0,))


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    root = tmp_path_factory.mktemp("drift")
    plan, shots = capture_script(SCENE, SPEC, root / "planned", seed=5)
    camera = root / "camera"
    ScriptedCamera(camera, [s.png for s in shots]).run(chunk_delay_s=0, photo_delay_s=0)
    return root, plan, shots, camera


def copy(root, name):
    shutil.copytree(root / "planned", root / name)
    return root / name


def test_bind_then_process_equals_process_alone_byte_for_byte(shot):
    root, plan, shots, camera = shot
    bound = copy(root, "bound")
    assert bind_session(bound, camera).ok  # measures every photograph into the cache
    after_bind = process_session(bound, jobs=1)
    assert after_bind.n_cached == len(shots) and after_bind.n_measured == 0
    alone = copy(root, "alone")
    for s in shots:
        path = alone / plan.rows[s.row]["image"]
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(s.png)
    by_process = process_session(alone, jobs=1)
    assert by_process.n_measured == len(shots)
    assert after_bind.measurements_path.read_bytes() == by_process.measurements_path.read_bytes()


def test_a_vanished_camera_folder_is_an_error_naming_it(shot, capsys):
    root, plan, shots, camera = shot
    session = copy(root, "card_out")
    card = root / "card"
    shutil.copytree(camera, card)
    bind_session(session, card)
    table = process_session(session, jobs=1).measurements_path
    before = table.read_bytes()
    card.rename(root / "card_elsewhere")
    with pytest.raises(SessionError, match=r"card: the camera folder named in .*binding\.json is not "
                       r"there \(a card removed, a share not mounted, a folder renamed\?\); 18 row\(s\) "
                       r"are bound to files in it") as exc:
        process_session(session, jobs=1)
    assert exc.value.reason == "camera_dir_missing"
    assert main(["process", str(session), "-q"]) == 2
    assert f"{card}: the camera folder" in capsys.readouterr().err
    assert table.read_bytes() == before  # nothing rewritten as pending


def test_markers_of_the_other_polarity_are_measured_with_a_note(tmp_path):
    import dataclasses

    import cv2

    from vision_torsion.measurements import read_measurements
    from vision_torsion.synthetic.render import render

    tiny = Scene(image=ImageSpec(320, 240), disk=DiskSpec(center_x=160.3, center_y=120.4, background_level=200.0),
                 markers=MarkerSpec(radius_px=10.0, distance_px=90.0, positions_deg=(10.0, 190.0)), name="tiny")
    plan, shots = capture_script(tiny, SPEC, tmp_path / "s", seed=2)
    bright = dataclasses.replace(tiny, markers=dataclasses.replace(tiny.markers, polarity="bright", level=240.0),
                                 disk=dataclasses.replace(tiny.disk, background_level=60.0))
    for s in shots:
        data = s.png
        if s.row == 4:  # the lights changed for this one: bright markers on a dark disk
            _, buf = cv2.imencode(".png", render(bright, SPEC.angle_sign * s.angle_deg, seed=4).image)
            data = buf.tobytes()
        path = tmp_path / "s" / plan.rows[s.row]["image"]
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(data)
    res = process_session(tmp_path / "s", jobs=1)
    table = read_measurements(res.measurements_path)
    assert res.ok and list(table["status"]) == ["ok"] * 18
    assert list(table["message"].fillna("").astype(bool)) == [k == 4 for k in range(18)]
    assert table["message"].iloc[4] == ("note: the markers are bright here, the session's are dark (the "
                                   "lighting changed?); measured all the same")
    # measured correctly: the angle noise is ~0.001°; 0.01° is far below a step (0.25°)
    assert abs(table["angle_deg"].iloc[4] - shots[4].angle_deg) < 0.01


def _session_with(tmp_path, scene, replaced: dict):
    """A captured session of `scene` whose rows in `replaced` hold
    ``replaced[row](image, angle_deg)`` instead of their image; its table and shots."""
    import cv2
    import numpy as np

    from vision_torsion.measurements import read_measurements
    from vision_torsion.synthetic.render import render

    plan, shots = capture_script(scene, SPEC, tmp_path / "s", seed=2)
    for s in shots:
        data = s.png
        if s.row in replaced:
            image = render(scene, SPEC.angle_sign * s.angle_deg, seed=4).image
            data = cv2.imencode(".png", np.clip(np.rint(replaced[s.row](image, s.angle_deg)), 0, 255)
                                .astype(np.uint8))[1].tobytes()
        path = tmp_path / "s" / plan.rows[s.row]["image"]
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(data)
    return read_measurements(process_session(tmp_path / "s", jobs=1).measurements_path), shots


# a disk inside a dark surround: inverted, the dark-marker search finds no target
_RIMMED = Scene(image=ImageSpec(480, 360), disk=DiskSpec(center_x=240.3, center_y=180.4, background_level=200.0,
                                                        radius_px=160.0, outside_level=20.0),
                markers=MarkerSpec(radius_px=16.0, distance_px=110.0, positions_deg=(10.0, 190.0)), name="rimmed")


def test_a_whole_frame_inverted_is_measured_by_the_other_polarity_with_a_note(tmp_path):
    table, shots = _session_with(tmp_path, _RIMMED, {4: lambda image, angle: 255.0 - image})
    assert list(table["status"]) == ["ok"] * 18
    assert table["message"].iloc[4] == ("note: the markers are bright here, the session's are dark (the "
                                   "lighting changed?); measured all the same")
    assert abs(table["angle_deg"].iloc[4] - shots[4].angle_deg) < 0.01  # noise ~0.001°, a step 0.25°


def test_two_markers_of_the_other_polarity_at_another_separation_are_not_the_target(tmp_path):
    import dataclasses

    from vision_torsion.synthetic.render import render

    closer = dataclasses.replace(_RIMMED, markers=dataclasses.replace(_RIMMED.markers, distance_px=80.0))
    table, _ = _session_with(tmp_path, _RIMMED, {4: lambda image, angle: 255.0 - render(
        closer, SPEC.angle_sign * angle, seed=4).image})
    assert table["status"].iloc[4] == "failed"
    assert table["message"].iloc[4] == ("no target of the session's polarity (dark) found, and the two markers of "
                                       "the other polarity are 160.0 px apart where the reference's are 220.0 px: "
                                       "not the target")
    assert [status for k, status in enumerate(table["status"]) if k != 4] == ["ok"] * 17


def test_a_blurred_photograph_is_suspect_in_process_by_the_rule_of_watch_and_bind(tmp_path):
    from vision_torsion.measurements import read_measurements

    tiny = Scene(image=ImageSpec(320, 240), disk=DiskSpec(center_x=160.3, center_y=120.4, background_level=200.0),
                 markers=MarkerSpec(radius_px=10.0, distance_px=90.0, positions_deg=(10.0, 190.0)), name="tiny")
    plan, shots = capture_script(tiny, SPEC, tmp_path / "s", seed=6, blurred=7)
    for s in shots:
        path = tmp_path / "s" / plan.rows[s.row]["image"]
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(s.png)
    res = process_session(tmp_path / "s", jobs=1)
    table = read_measurements(res.measurements_path)
    assert res.suspect == (plan.rows[7]["image"],)
    assert table["message"].iloc[7].startswith("blurred: marker edges ")
    assert table["message"].iloc[7].endswith(" px in the reference (camera shake, or focus?); shoot it again")
    camera = tmp_path / "camera"
    ScriptedCamera(camera, [s.png for s in shots]).run(chunk_delay_s=0, photo_delay_s=0)
    told = bind_session(tmp_path / "s", camera, write=False).diagnoses
    assert [t.split(": ", 2)[-1] for t in told] == [table["message"].iloc[7]]  # the same words


def test_bind_keeps_the_row_of_a_half_written_file_and_process_fails_it(tmp_path, capsys):
    tiny = Scene(image=ImageSpec(320, 240), disk=DiskSpec(center_x=160.3, center_y=120.4, background_level=200.0),
                 markers=MarkerSpec(radius_px=10.0, distance_px=90.0, positions_deg=(10.0, 190.0)), name="tiny")
    plan, shots = capture_script(tiny, SPEC, tmp_path / "s", seed=8)
    camera = tmp_path / "camera"
    photos = [s.png for s in shots]
    photos[5] = photos[5][: len(photos[5]) // 2]  # the card stalled half-way through IMG_0006
    ScriptedCamera(camera, photos).run(chunk_delay_s=0, photo_delay_s=0)
    res = bind_session(tmp_path / "s", camera)
    assert [res.binding.images[row["image"]] for row in plan.rows] == [f"IMG_{k:04d}.png" for k in range(1, 19)]
    (said,) = [t for t in res.diagnoses if t.startswith("IMG_0006.png")]
    assert said.startswith("IMG_0006.png (line 7: orientation 0, cycle 1, positive_unloading, step 4): "
                           "not measured: ")
    assert said.endswith(" (a half-written file? it keeps its row)")
    assert not res.ok
    assert main(["process", str(tmp_path / "s"), "-q"]) == 1  # not 0, as if all were well
