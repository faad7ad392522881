"""The scripted camera at the rig: each capture mistake is reported by ``watch`` at
that image or the next, with the right diagnosis, and by ``bind`` afterwards with
the fix; a clean session gives no warning at all (none said and withdrawn).

One orientation of the paper's bilinear gear (18 rows: the reference, +T_max, then
four steps per phase) on the small 320×240 scene of test_rig_capture. Rows
(0-based): 0 reference, 1-5 positive unloading, 6-9 negative loading, 10-13
negative unloading, 14-17 positive loading; CSV line = row + 2.
"""

import re
from pathlib import Path

import pytest

from vision_torsion.session.bind import bind_session
from vision_torsion.session.watch import Watcher
from vision_torsion.synthetic import Scene
from vision_torsion.synthetic.scene import DiskSpec, ImageSpec, MarkerSpec
from vision_torsion.synthetic.scripted_camera import ScriptedCamera, capture_script
from vision_torsion.synthetic.session import SessionSpec

SCENE = Scene(image=ImageSpec(320, 240),
              disk=DiskSpec(center_x=160.3, center_y=120.4, background_level=200.0),
              markers=MarkerSpec(radius_px=10.0, distance_px=90.0, positions_deg=(10.0, 190.0)),
              name="tiny")
SPEC = SessionSpec(max_torque_nm=0.07848, orientations_deg=(0.0,))

# mistake -> (capture_script options, the file warned first, what watch says of it
# (a pattern), the bind fix or diagnosis (a pattern))
CASES = {
    "missed shot": ({"missed": 8}, ("IMG_0009.png", "IMG_0010.png"), r"a missed shot",
                    r"--missing 10\b"),
    "extra shot": ({"extra_after": 11}, ("IMG_0013.png",), r"no movement.*an extra shot",
                   r"--skip IMG_0013\.png"),
    "forgotten weight": ({"forgotten": 3}, ("IMG_0004.png", "IMG_0005.png"),
                         r"a weight piece forgotten on a pan", r"a weight piece forgotten"),
    "swapped shots": ({"swapped": 11}, ("IMG_0012.png", "IMG_0013.png"),
                      r"IMG_0012\.png and IMG_0013\.png look swapped.*--swap IMG_0012\.png IMG_0013\.png",
                      r"--swap IMG_0012\.png IMG_0013\.png"),
    "camera bump 1 px": ({"bumped": (9, 1.0, 0.0, 0.0)}, ("IMG_0010.png", "IMG_0011.png"),
                         r"the camera or the target moved", r"the camera or the target moved"),
    "camera bump 3 px and 0.05°": ({"bumped": (6, 3.0, 0.0, 0.05)}, ("IMG_0007.png", "IMG_0008.png"),
                                   r"the camera or the target moved", r"the camera or the target moved"),
    "blur": ({"blurred": 7}, ("IMG_0008.png",), r"blurred", r"IMG_0008\.png .*blurred"),
}


def shoot(tmp_path, options, *, seed=11):
    """Plan, render and put the photographs in a camera folder (old file times,
    20 s apart: complete at once, in capture order)."""
    session = tmp_path / "session"
    plan, shots = capture_script(SCENE, SPEC, session, seed=seed, **options)
    camera = tmp_path / "camera"
    ScriptedCamera(camera, [s.png for s in shots]).run(chunk_delay_s=0, photo_delay_s=0)
    return session, camera, len(shots)


def watch(session, camera, n):
    """Watch the camera folder as the photographs arrive one by one; the events."""
    photos = sorted(camera.iterdir())
    hidden = camera.parent / "later"
    hidden.mkdir()
    for p in photos:
        p.rename(hidden / p.name)
    clock = [0.0]
    events = []
    with Watcher(session, camera_dir=camera, page=False, clock=lambda: clock[0]) as w:
        for p in photos:
            (hidden / p.name).rename(p)
            clock[0] += 2.0
            events += w.tick()
    shown = [e.file for e in events if e.kind == "shot"]
    assert shown == [p.name for p in photos][:len(shown)] and len(shown) == min(n, 18)
    return events


def warnings(events):
    """[(file, message, file of the photograph last shown when it came)]."""
    out, last = [], None
    for e in events:
        if e.kind == "shot":
            last = e.file
        elif e.kind == "warning":
            out.append((e.file, e.message, last))
    return out


@pytest.mark.parametrize("mistake", list(CASES))
def test_each_mistake_is_reported_at_that_image_or_the_next(tmp_path, mistake):
    options, files, said, fix = CASES[mistake]
    session, camera, n = shoot(tmp_path, options)
    events = watch(session, camera, n)
    found = warnings(events)
    assert found, f"{mistake}: watch said nothing"
    first_file, message, when = found[0]
    assert first_file in files and re.search(said, message), (mistake, found)
    names = sorted(p.name for p in camera.iterdir())
    assert names.index(when) - names.index(files[0]) <= 1  # at that image or the next
    assert not [e for e in events if e.kind == "retracted"]
    res = bind_session(session, camera, write=False)
    told = "\n".join([f.message for f in res.fixes] + list(res.diagnoses) + list(res.remaining)
                     + ([res.command] if res.command else []))
    assert re.search(fix, told), (mistake, told)
    assert not res.ok


def test_a_wrong_angle_sign_is_one_line_and_no_skips(tmp_path):
    session, camera, n = shoot(tmp_path, {})
    toml = Path(session) / "session.toml"
    toml.write_text(toml.read_text().replace("angle_sign = 1", "angle_sign = -1"))
    found = warnings(watch(session, camera, n))
    assert len(found) == 1, found
    file, message, when = found[0]
    assert file == when == "IMG_0002.png"  # the first loaded image
    assert re.search(r"angle_sign is inverted: this first loaded image turned -\d+\.\d{4}° under "
                     r"\+0\.07848 N·m; set angle_sign = \+1 in .*session\.toml", message)
    res = bind_session(session, camera, write=False)
    assert not res.fixes and not res.warnings and not res.remaining and res.command is None
    (line,) = res.diagnoses
    assert line.startswith("angle_sign is inverted: the first loaded image turned against the "
                           "torque in 1 of 1 orientation(s) (IMG_0002.png, line 3")
    assert line.endswith("set angle_sign = +1 in " + str(toml) + " (the steps are checked with it)")


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_clean_sessions_give_no_warning_at_all(tmp_path, seed):
    session, camera, n = shoot(tmp_path, {}, seed=seed)
    events = watch(session, camera, n)
    assert not [e for e in events if e.kind in ("warning", "retracted")]
    res = bind_session(session, camera, write=False)
    assert res.ok and not res.fixes and not res.diagnoses
