"""Watch and bind that cannot drift: one result per cache key whichever command
measures first, and a vanished camera folder is an error naming it."""

import shutil

import pytest

from vision_torsion.cli import main
from vision_torsion.errors import SessionError
from vision_torsion.session import process_session
from vision_torsion.session.bind import bind_session
from vision_torsion.synthetic import Scene
from vision_torsion.synthetic.camera import ScriptedCamera, capture_script
from vision_torsion.synthetic.scene import DiskSpec, ImageSpec, MarkerSpec
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
