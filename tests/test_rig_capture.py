"""At the rig: a scripted camera with an extra shot, a missed shot and a forgotten
weight; ``bind`` finds them and proposes the fix; after binding, measurements.csv is
the same as the same photographs' under the planned names.

The session: the synthetic renderer (:mod:`vision_torsion.synthetic.scripted_camera`) on a
small 320×240 scene, two orientations of four steps per phase (36 rows), the
paper's bilinear model (k_u = 4.4, k_l = 0.3 N·m/rad, τ_c = 0.15 N·m): steps of
0.255° on the stiff branch and 3.75° on the soft one, angle noise ~0.001°.
"""

import shutil

import pytest

from vision_torsion.cli import main
from vision_torsion.session import process_session
from vision_torsion.session.bind import bind_session
from vision_torsion.synthetic import Scene
from vision_torsion.synthetic.scene import DiskSpec, ImageSpec, MarkerSpec
from vision_torsion.synthetic.scripted_camera import ScriptedCamera, capture_script
from vision_torsion.synthetic.session import SessionSpec

SCENE = Scene(image=ImageSpec(320, 240),
              disk=DiskSpec(center_x=160.3, center_y=120.4, background_level=200.0),
              markers=MarkerSpec(radius_px=10.0, distance_px=90.0, positions_deg=(10.0, 190.0)),
              name="tiny")
SPEC = SessionSpec(max_torque_nm=0.0785, orientations_deg=(0.0, 60.0))
# rows (0-based): 3 = o0 positive_unloading s2 (CSV line 5), 7 = o0 negative_loading s2
# (line 9), 25 = o60 negative_loading s2 (line 27)
FORGOTTEN, EXTRA_AFTER, MISSED = 3, 7, 25


@pytest.fixture(scope="module")
def script(tmp_path_factory):
    root = tmp_path_factory.mktemp("rig")
    plan, shots = capture_script(SCENE, SPEC, root / "planned", seed=3, forgotten=FORGOTTEN,
                                 extra_after=EXTRA_AFTER, missed=MISSED)
    return root, plan, shots


def copy_session(root, name):
    dst = root / name
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(root / "planned", dst, ignore=shutil.ignore_patterns("results", "images"))
    return dst


def test_bind_finds_the_extra_and_the_missed_shot_and_the_forgotten_weight(script, capsys):
    root, plan, shots = script
    camera = root / "camera_a"
    ScriptedCamera(camera, [s.png for s in shots]).run(chunk_delay_s=0, photo_delay_s=0)
    session = copy_session(root, "bound")
    res = bind_session(session, camera)
    assert res.n_files == res.n_rows == 36  # the count fits: only the angles tell
    assert [(f.kind, f.file, f.line) for f in res.fixes] == [
        ("skip", "IMG_0009.png", 10), ("missing", "IMG_0027.png", 27), ("drop", "IMG_0004.png", 5)]
    assert res.command.endswith("--by time --skip IMG_0009.png --skip IMG_0004.png --missing 27 --missing 5")
    assert res.remaining == ()
    assert not res.ok
    # apply the binding fixes from the command line, keeping the photograph of the wrong load
    assert main(["bind", str(session), str(camera), "--skip", "IMG_0009.png",
                 "--missing", "27"]) == 1  # still 1: the forgotten weight is listed, with its fix
    out, err = capsys.readouterr()
    assert "proposed fix: IMG_0004.png (line 5: orientation 0, cycle 1, positive_unloading, step 2) shows" in out
    assert "step does not fit: IMG_0004.png (line 5: orientation 0, cycle 1, positive_unloading" in err
    assert "a weight piece forgotten on a pan (or taken off too early)" in err
    bound = process_session(session, jobs=1)
    # the same photographs under the planned names
    named = copy_session(root, "named")
    files = [s for s in shots if s.kind != "extra"]
    for shot in files:
        (named / plan.rows[shot.row]["image"]).parent.mkdir(exist_ok=True)
        (named / plan.rows[shot.row]["image"]).write_bytes(shot.png)
    reference = process_session(named, jobs=1)
    assert bound.n_pending == reference.n_pending == 1
    assert bound.measurements_path.read_bytes() == reference.measurements_path.read_bytes()
    assert bound.unlisted == ()  # IMG_0009.png was left out on purpose (--skip)


def test_clean_capture_binds_without_warnings(script):
    root, plan, _ = script
    _, shots = capture_script(SCENE, SPEC, root / "clean", seed=4)
    camera = root / "camera_clean"
    ScriptedCamera(camera, [s.png for s in shots]).run(chunk_delay_s=0, photo_delay_s=0)
    res = bind_session(root / "clean", camera)
    assert res.ok and not res.fixes and not res.warnings


def test_bind_by_name_and_the_camera_folder_is_never_written(script):
    root, plan, shots = script
    camera = root / "camera_name"
    # written in reverse time: capture order by time would reverse them
    cam = ScriptedCamera(camera, [s.png for s in shots[:5]], start_time=1.7e9, interval_s=-10.0)
    cam.run(chunk_delay_s=0, photo_delay_s=0)
    (camera / "IMG_0003.THM").write_bytes(b"thumbnail")
    shutil.copy(camera / "IMG_0002.png", camera / "IMG_0002 copy.png")
    before = {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in camera.iterdir()}
    session = copy_session(root, "by_name")
    res = bind_session(session, camera, by="name")
    assert [res.binding.images[plan.rows[i]["image"]] for i in range(5)] == [
        f"IMG_{k:04d}.png" for k in range(1, 6)]
    assert dict(res.ignored) == {
        "IMG_0002 copy.png": "the same bytes as IMG_0002.png (a copy, not a new photograph); not bound",
        "IMG_0003.THM": "not an image file (expected .png, .tif, .tiff, .bmp, .jpg, .jpeg); not bound"}
    assert len(res.unphotographed) == 31 and not res.leftovers
    by_time = bind_session(session, camera, write=False)
    assert by_time.binding.images[plan.rows[0]["image"]] == "IMG_0005.png"
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in camera.iterdir()} == before


def test_bind_lists_leftover_files(script):
    root, plan, shots = script
    camera = root / "camera_more"
    ScriptedCamera(camera, [s.png for s in shots] + [shots[-1].png[:-1] + b"\0"]).run(
        chunk_delay_s=0, photo_delay_s=0)
    res = bind_session(copy_session(root, "more"), camera, write=False)
    assert res.leftovers == ("IMG_0037.png",)



# -- watch -------------------------------------------------------------------------

def watch_script(watcher, camera, photos, clock, *, pause_in=None):
    """Let the scripted camera write `photos` in 4 kB chunks, one watcher tick per
    chunk, 0.3 s of (fake) time apart; in photograph `pause_in` the camera stalls for
    3 s half-way (the file looks settled but is not complete)."""
    events = []
    cam = ScriptedCamera(camera, photos, chunk_bytes=4096)
    for path, complete in cam.steps():
        clock[0] += 0.3
        if pause_in is not None and path.name == f"IMG_{pause_in:04d}.png" and not complete \
                and path.stat().st_size == 8192:
            for _ in range(10):
                clock[0] += 0.3
                events += watcher.tick()
        events += watcher.tick()
    for _ in range(3):
        clock[0] += 1.0
        events += watcher.tick()
    return events


def test_watch_flags_each_mistake_on_the_image_where_it_happens(script):
    root, plan, shots = script
    from vision_torsion.session.watch import Watcher

    session, camera, clock = copy_session(root, "watched"), root / "camera_w", [0.0]
    with Watcher(session, camera_dir=camera, settle_s=1.0, clock=lambda: clock[0]) as w:
        events = watch_script(w, camera, [s.png for s in shots], clock, pause_in=6)
    bound = [e for e in events if e.kind == "shot"]
    # each once, in order; after the extra shot (IMG_0009.png) orientation 0's files are a
    # row late: its last one is set aside, so that orientation 120's bind to its own rows
    assert [e.file for e in bound] == [f"IMG_{k:04d}.png" for k in range(1, 37) if k != 19]
    assert [(e.kind, e.file) for e in events if e.kind in ("ignored", "deleted", "leftover")] == [
        ("ignored", "IMG_0019.png")]
    warned = [e for e in events if e.kind == "warning"]
    first = {}
    for e in warned:
        first.setdefault(e.file, e.message)
    # nothing before the forgotten weight; then each mistake on its own image
    assert min(first) == "IMG_0004.png"
    assert "a weight piece forgotten on a pan (or taken off too early); fix: " in first["IMG_0004.png"]
    assert first["IMG_0004.png"].endswith("--skip IMG_0004.png --missing 5")
    assert "no movement" in first["IMG_0009.png"]
    assert first["IMG_0009.png"].endswith("--skip IMG_0004.png --missing 5 --skip IMG_0009.png")  # all so far
    assert "two planned steps in one: a missed shot (this photograph shows the next row's load); fix: " in \
        first["IMG_0027.png"]  # line 27 missed: IMG_0027.png, bound to it, shows line 28's load
    assert first["IMG_0027.png"].endswith("--skip IMG_0004.png --missing 5 --skip IMG_0009.png --missing 27")
    # every warning comes with the image's own event or the next image's (a step out
    # of line waits for the next to tell a mistake from the gear's stiffness switching)
    shots_so_far = []
    for e in events:
        if e.kind == "shot":
            shots_so_far.append(e.file)
        if e.kind == "warning":
            assert e.file in shots_so_far[-2:]
    assert not [e for e in events if e.kind == "retracted"]  # nothing said and withdrawn
    # decided by the next image: the page never says "the next step will tell"
    (kept,) = [p for p in w.live_points() if p.file == "IMG_0004.png"]
    assert "forgotten on a pan (or taken" in kept.warnings[0] and "next step will tell" not in kept.warnings[0]
    page = (session / "results" / "live.html").read_text()
    assert "IMG_0027.png" in page and not w.complete  # the files a row early: line 37 waits
    # bind afterwards proposes the fix; the camera folder was never written
    res = bind_session(session, camera, write=False)
    assert [(f.kind, f.file, f.line) for f in res.fixes] == [
        ("skip", "IMG_0009.png", 10), ("missing", "IMG_0027.png", 27), ("drop", "IMG_0004.png", 5)]


def test_watch_in_real_time_and_resume(script, tmp_path):
    import threading

    from vision_torsion.session.watch import watch_session

    root, plan, shots = script
    session, camera = copy_session(root, "live"), tmp_path / "cam"
    cam = ScriptedCamera(camera, [s.png for s in shots[:5]], chunk_bytes=8192)
    stop = threading.Event()
    seen = []

    def shoot():
        cam.run(chunk_delay_s=0.002, photo_delay_s=0.01)
        threading.Timer(1.0, stop.set).start()

    threading.Thread(target=shoot).start()
    res = watch_session(session, camera_dir=camera, poll_s=0.02, settle_s=0.1,
                        stop=stop, echo=seen.append)
    assert res.n_bound == 5 and not res.interrupted
    # resumed: the same five files, from the cache, bound to the same rows
    again = []
    stop.set()
    from vision_torsion.session.watch import Watcher

    with Watcher(session, camera_dir=camera, settle_s=0.1) as w:
        again = [e.file for e in w.tick() if e.kind == "shot"]
        assert all(t["cached"] for t in w.timings)
    assert again == [f"IMG_{k:04d}.png" for k in range(1, 6)]
