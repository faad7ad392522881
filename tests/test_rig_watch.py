"""watch's bad input, one test per message; the camera folder is never written.

A fake clock drives Watcher.tick: no test waits in real time."""

import os
import re
import shutil

import cv2
import numpy as np
import pytest
from helpers import draw_target, make_session, mount_tmpfs, tree_digest

from vision_torsion.errors import SessionError
from vision_torsion.images import write_image
from vision_torsion.session.watch import Watcher


@pytest.fixture
def rig(tmp_path):
    """A planned 10-row session (no images) and an empty camera folder."""
    folder = tmp_path / "s"
    plan, truth = make_session(folder, orientations=(0,))
    photos = {}
    for row in plan.rows:
        photos[row["image"]] = (folder / row["image"]).read_bytes()
        (folder / row["image"]).unlink()
    cam = tmp_path / "cam"
    cam.mkdir()
    return folder, cam, plan, photos


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def put(cam, name, data, *, old=True):
    (cam / name).write_bytes(data)
    if old:  # written a while ago: complete at once
        os.utime(cam / name, (1.7e9, 1.7e9))


def run(watcher, clock, ticks=2):
    events = []
    for _ in range(ticks):
        clock.t += 1.5
        events += watcher.tick()
    return events


def messages(events, kind):
    return [e.message for e in events if e.kind == kind]


def test_a_non_image_is_set_aside(rig):
    folder, cam, plan, photos = rig
    put(cam, "IMG_0001.THM", b"thumbnail")
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        assert messages(run(w, clock), "ignored") == [
            "IMG_0001.THM: not an image file (expected .png, .tif, .tiff, .bmp, .jpg, .jpeg); not bound"]


def test_a_copy_is_set_aside(rig):
    folder, cam, plan, photos = rig
    first = photos[plan.rows[0]["image"]]
    put(cam, "IMG_0001.png", first)
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        run(w, clock)
        shutil.copy(cam / "IMG_0001.png", cam / "IMG_0001 (2).png")
        assert messages(run(w, clock), "ignored") == [
            "IMG_0001 (2).png: the same bytes as IMG_0001.png (a copy, not a new photograph); not bound"]


def test_more_photographs_than_planned(rig):
    folder, cam, plan, photos = rig
    for k, row in enumerate(plan.rows):
        put(cam, f"IMG_{k + 1:04d}.png", photos[row["image"]])
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        events = run(w, clock)
        assert messages(events, "complete") == ["all 10 planned images are in"]
        write_image(cam / "IMG_0011.png", draw_target(7.0))
        os.utime(cam / "IMG_0011.png", (1.8e9, 1.8e9))
        assert messages(run(w, clock), "leftover") == [
            "IMG_0011.png: every planned row already has its photograph (10 rows); not bound "
            "(an extra shot?)"]


def test_a_file_deleted_before_it_was_complete(rig):
    folder, cam, plan, photos = rig
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        (cam / "IMG_0001.png").write_bytes(photos[plan.rows[0]["image"]][:100])
        assert w.tick() == []  # just seen: not settled yet
        (cam / "IMG_0001.png").unlink()
        assert messages(run(w, clock, 1), "deleted") == [
            "IMG_0001.png was deleted before it was complete; not bound"]


def test_a_file_deleted_after_it_was_measured(rig):
    folder, cam, plan, photos = rig
    put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]])
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        run(w, clock)
        (cam / "IMG_0001.png").unlink()
        assert messages(run(w, clock, 1), "deleted") == [
            "IMG_0001.png was deleted after it was measured, bound to line 2: orientation 0, "
            "cycle 1, reference, step 0; its measurement is kept (cache), but process and bind "
            "will need the file back"]


def test_the_camera_folder_disappears_and_comes_back(rig):
    folder, cam, plan, photos = rig
    put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]])
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        run(w, clock)
        cam.rename(cam.with_name("away"))
        gone = run(w, clock, 3)
        assert messages(gone, "folder_gone") == [
            f"{cam}: the camera folder has disappeared; waiting for it to come back (nothing "
            "measured so far is lost; Ctrl-C to stop)"]
        cam.with_name("away").rename(cam)
        put(cam, "IMG_0002.png", photos[plan.rows[1]["image"]])
        back = run(w, clock)
        assert messages(back, "folder_back") == [f"{cam}: the camera folder is back"]
        assert [e.file for e in back if e.kind == "shot"] == ["IMG_0002.png"]
        assert len(w.bound) == 2


def test_a_stalled_file_holds_its_row_and_the_files_after_it_wait(rig):
    folder, cam, plan, photos = rig
    first = photos[plan.rows[0]["image"]]
    put(cam, "IMG_0001.png", first[:-30])  # no IEND: stalled half-way
    put(cam, "IMG_0002.png", photos[plan.rows[1]["image"]])
    os.utime(cam / "IMG_0002.png", (1.8e9, 1.8e9))  # taken after it
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock, give_up_s=10.0) as w:
        assert run(w, clock, 6) == []  # waited for, and IMG_0002 waits behind it
        events = run(w, clock, 2)
        (stalled,) = [e.message for e in events if e.kind == "warning"]
        assert stalled.startswith("IMG_0001.png (line 2: orientation 0, cycle 1, reference, step 0): "
                                  "still not a complete image after 10 s (IMG_0001.png: ")
        assert stalled.endswith("bound to this row as failed, so that the photographs after it keep "
                                "their rows. It is measured again when it changes; if it is not a "
                                "photograph of this row, leave it out with `vision-torsion bind "
                                "--skip IMG_0001.png`")
        assert [e.file for e in events if e.kind == "shot"] == ["IMG_0001.png", "IMG_0002.png"]
        assert {b.file: b.row.line for b in w.bound.values()} == {"IMG_0001.png": 2, "IMG_0002.png": 3}
        # the card finally delivers the rest: measured again, announced, warning gone
        put(cam, "IMG_0001.png", first)
        events = run(w, clock, 2)
        assert messages(events, "replaced") == [
            "IMG_0001.png changed after it was measured (a re-shot, or a file written late): "
            "measured again for line 2: orientation 0, cycle 1, reference, step 0; its old "
            "result is dropped"]
        assert not [b for b in w.bound.values() if b.warnings]


def test_a_stalled_file_fails_its_row_in_process(rig):
    from vision_torsion.session import process_session

    folder, cam, plan, photos = rig
    put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]][:-30])
    put(cam, "IMG_0002.png", photos[plan.rows[1]["image"]])
    os.utime(cam / "IMG_0002.png", (1.8e9, 1.8e9))
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock, give_up_s=3.0) as w:
        run(w, clock, 4)
    res = process_session(folder, jobs=1)
    # the reference failed, so the row after it has no angle either: not pending, failed
    assert not res.ok and [image for image, _ in res.failures] == [plan.rows[0]["image"], plan.rows[1]["image"]]
    assert "truncated PNG" in res.failures[0][1] and "reference image" in res.failures[1][1]


#: What watch says when the photograph bound to the plan's line 3 (IMG_0002.png) is
#: replaced after it was measured.
SECOND_REPLACED = (
    "IMG_0002.png changed after it was measured (a re-shot, or a file written late): "
    "measured again for line 3: orientation 0, cycle 1, positive_unloading, step 0; its "
    "old result is dropped")


def test_a_reshot_under_the_same_name_is_measured_again(rig):
    folder, cam, plan, photos = rig
    put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]])
    put(cam, "IMG_0002.png", photos[plan.rows[1]["image"]])
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        run(w, clock)
        before = w.bound[1].angle
        # the camera writes the re-shot over the old file (not the tool: its folder contract would refuse)
        (cam / "IMG_0002.png").write_bytes(cv2.imencode(".png", draw_target(7.0))[1].tobytes())
        os.utime(cam / "IMG_0002.png", (1.8e9, 1.8e9))
        events = run(w, clock)
        assert messages(events, "replaced") == [SECOND_REPLACED]
        assert [e.file for e in events if e.kind == "shot"] == ["IMG_0002.png"]
        (point,) = [p for p in w.live_points() if p.file == "IMG_0002.png"]
        assert point.angle_deg == w.bound[1].angle != before
        assert len(w.bound) == 2


def warnings_of(rig, second):
    folder, cam, plan, photos = rig
    put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]])
    write_image(cam / "IMG_0002.png", second)
    os.utime(cam / "IMG_0002.png", (1.8e9, 1.8e9))
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        return [e.message for e in run(w, clock) if e.kind == "warning" and e.file == "IMG_0002.png"]


def test_marker_not_found(rig):
    (msg,) = warnings_of(rig, np.full((150, 200), 220, np.uint8))
    assert msg.startswith("IMG_0002.png (line 3: orientation 0, cycle 1, positive_unloading, "
                          "step 0): marker not found: IMG_0002.png: found 0 usable marker(s)")


def test_saturated_image(rig):
    img = draw_target(5.0)
    img[:20, :] = 255  # 13 % of the pixels clipped
    assert warnings_of(rig, img) == [
        "IMG_0002.png (line 3: orientation 0, cycle 1, positive_unloading, step 0): saturated: "
        "13.3 % of the pixels at full scale (shorten the exposure or dim the light)"]


def test_blurred_image(rig):
    img = cv2.GaussianBlur(draw_target(5.0), (0, 0), 3.0)
    (msg,) = warnings_of(rig, img)
    assert "blurred: marker edges" in msg and "(camera shake, or focus?)" in msg


def test_two_markers_of_the_other_polarity_at_another_separation_are_not_the_target(rig):
    from helpers import ARM_PX

    (msg,) = warnings_of(rig, 255 - draw_target(5.0, arm_px=0.7 * ARM_PX))  # bright, and closer together
    assert msg.startswith("IMG_0002.png (line 3: orientation 0, cycle 1, positive_unloading, step 0): no target of "
                          "the session's polarity (dark) found, and the two markers of the other polarity are ")
    assert msg.endswith(" px apart where the reference's are {:.1f} px: not the target".format(2 * ARM_PX))


def test_the_camera_folder_is_never_written(rig):
    folder, cam, plan, photos = rig
    for k, row in enumerate(plan.rows[:4]):
        put(cam, f"IMG_{k + 1:04d}.png", photos[row["image"]])
    (cam / "notes.txt").write_text("x")
    before = tree_digest(cam)
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        run(w, clock)
    assert tree_digest(cam) == before
    assert (folder / "binding.json").is_file() and (folder / "results" / "live.html").is_file()


@pytest.mark.parametrize("option, value", [("settle_s", -1.0), ("give_up_s", float("inf"))])
def test_times_must_be_finite_seconds(rig, option, value):
    folder, cam, plan, photos = rig
    with pytest.raises(SessionError, match=rf"{option} = {value!r}: expected a finite number of seconds >= 0"):
        Watcher(folder, camera_dir=cam, **{option: value})


def test_camera_folder_cannot_be_the_output_folder(rig):
    folder, cam, *_ = rig
    with pytest.raises(SessionError, match="the camera folder cannot be the output folder"):
        Watcher(folder, camera_dir=cam, out_dir=cam)


def test_files_saved_under_the_planned_names_bind_by_name(rig):
    folder, cam, plan, photos = rig
    # no camera folder: SESSION/images, the second row photographed first
    for row in (plan.rows[1], plan.rows[0]):
        put(folder, row["image"], photos[row["image"]])
    clock = Clock()
    with Watcher(folder, clock=clock) as w:
        shots = [e for e in run(w, clock) if e.kind == "shot"]
    assert [(e.file, e.line) for e in shots] == [(plan.rows[0]["image"][7:], 2),
                                                 (plan.rows[1]["image"][7:], 3)]


def test_watch_command_ends_when_every_image_is_in(rig, capsys):
    from vision_torsion.cli import main

    folder, cam, plan, photos = rig
    for k, row in enumerate(plan.rows):
        put(cam, f"IMG_{k + 1:04d}.png", photos[row["image"]])
    status = main(["watch", str(folder), "--camera-dir", str(cam), "--settle", "0", "--poll", "0.01"])
    out, err = capsys.readouterr()
    # the support's angles jump 0.5° where the load reverses (its hysteresis): a step
    # may be flagged; the exit status says whether any photograph kept a warning
    warned = int(re.search(r"10 of 10 planned images bound; (\d+) with warnings", out).group(1))
    assert status == (1 if warned else 0)
    assert "  10/10  IMG_0010.png → line 11: orientation 0, cycle 1, positive_loading, step 2" in out
    assert (folder / "results" / "report.html").is_file()  # it ends with the report


def test_ctrl_c_stops_cleanly_and_keeps_everything(rig):
    from vision_torsion.session.watch import watch_session

    folder, cam, plan, photos = rig
    for k, row in enumerate(plan.rows[:3]):
        put(cam, f"IMG_{k + 1:04d}.png", photos[row["image"]])
    seen = []

    def echo(event):  # Ctrl-C right after the second photograph is shown
        seen.append(event)
        if event.kind == "shot" and event.file == "IMG_0002.png":
            raise KeyboardInterrupt

    res = watch_session(folder, camera_dir=cam, poll_s=0.01, settle_s=0.0, echo=echo)
    assert res.interrupted and seen[-1].message == "stopped; run the same command again to resume"
    # what was measured is kept: the binding is written and the cache holds the results
    from vision_torsion.session.binding import load_binding

    assert len(load_binding(folder).images) >= 2
    assert "finished" in (folder / "results" / "live.html").read_text()


@pytest.fixture
def read_only_session(tmp_path, rig):
    """The rig's session copied onto a tmpfs that is then made read-only (needs root)."""
    import subprocess

    folder, cam, plan, photos = rig
    mount = tmp_path / "ro"
    if not mount_tmpfs(mount, "size=4m"):
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        shutil.copytree(folder, mount / "s")
        if subprocess.run(["mount", "-o", "remount,ro", str(mount)], capture_output=True).returncode:
            pytest.skip("cannot remount the tmpfs read-only")
        yield mount / "s", cam, plan, photos
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True, timeout=20)


def test_a_read_only_session_folder_is_refused_before_the_first_photograph(read_only_session, tmp_path):
    from vision_torsion.errors import OutputError
    from vision_torsion.session.bind import bind_session

    folder, cam, plan, photos = read_only_session
    put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]])
    with pytest.raises(OutputError, match=re.escape(f"{folder / 'results'}: cannot create the output "
                                                    "folder (read-only file system)")):
        Watcher(folder, camera_dir=cam)
    # the results elsewhere, but binding.json still goes into the session folder
    with pytest.raises(OutputError, match=re.escape(f"{folder}: cannot write into the output folder "
                                                    "(read-only file system)")):
        Watcher(folder, camera_dir=cam, out_dir=tmp_path / "out")
    with pytest.raises(OutputError, match=re.escape(f"{folder}: cannot write into the output folder")):
        bind_session(folder, cam, out_dir=tmp_path / "out2")
    assert not (tmp_path / "out2" / ".cache").exists()  # nothing measured


def test_control_characters_in_file_names_are_printed_escaped(rig, capsys):
    import threading

    from vision_torsion.session.watch import watch_session

    folder, cam, plan, photos = rig
    put(cam, "IMG\x1b]0;owned\x07.png", photos[plan.rows[0]["image"]])
    put(cam, "IMG\x1b[2J.THM", b"thumbnail")
    stop = threading.Event()
    threading.Timer(1.0, stop.set).start()
    watch_session(folder, camera_dir=cam, poll_s=0.05, settle_s=0.0, stop=stop)
    out, err = capsys.readouterr()
    assert "\x1b" not in out + err and "\x07" not in out + err
    assert "IMG\\x1b]0;owned\\x07.png → line 2" in out
    assert "IMG\\x1b[2J.THM: not an image file" in err


# -- filesystem events, the polling fallback, the size limit ---------------------------


def write_closed(path, data, *, chunk=4096):
    """Written in chunks as a camera does, then closed: a new file (its time is now)."""
    with open(path, "wb") as fh:
        for at in range(0, len(data), chunk):
            fh.write(data[at:at + chunk])
            fh.flush()


def test_a_closed_file_is_taken_in_at_once_through_the_filesystem_events(rig):
    folder, cam, plan, photos = rig
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        assert w.events.active and w.events.why_polling == ""
        assert w.tick() == []
        write_closed(cam / "IMG_0001.png", photos[plan.rows[0]["image"]])
        assert w.wait(10.0)  # woken by the close, not by the timeout
        # the clock has not moved: no settling time has passed, the close says it is complete
        assert [e.file for e in w.tick() if e.kind == "shot"] == ["IMG_0001.png"]


def test_a_file_still_open_is_not_taken_in_before_it_is_closed(rig):
    folder, cam, plan, photos = rig
    data = photos[plan.rows[0]["image"]]
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w, open(cam / "IMG_0001.png", "wb") as fh:
        fh.write(data)
        fh.flush()  # all there, but the camera has not closed it: the settling rule applies
        w.wait(0.2)
        assert w.tick() == [] and not w.bound
        fh.close()
        assert w.wait(10.0)
        assert [e.file for e in w.tick() if e.kind == "shot"] == ["IMG_0001.png"]


def test_polling_only_waits_for_the_size_to_settle(rig):
    folder, cam, plan, photos = rig
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock, events="poll", settle_s=1.0) as w:
        assert not w.events.active and w.events.why_polling == "polling was asked for"
        write_closed(cam / "IMG_0001.png", photos[plan.rows[0]["image"]])
        assert not w.wait(0.05)  # no notifications: the timeout
        assert w.tick() == []  # first seen now: not settled yet
        clock.t += 1.0
        assert [e.file for e in w.tick() if e.kind == "shot"] == ["IMG_0001.png"]


def test_the_events_come_back_with_the_camera_folder(rig):
    folder, cam, plan, photos = rig
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        cam.rename(cam.with_name("away"))
        assert [e.kind for e in w.tick()] == ["folder_gone"]
        cam.mkdir()  # a new folder of the same name: the old one's notifications are gone
        assert [e.kind for e in w.tick()] == ["folder_back"]
        write_closed(cam / "IMG_0001.png", photos[plan.rows[0]["image"]])
        assert w.wait(10.0)
        assert [e.file for e in w.tick() if e.kind == "shot"] == ["IMG_0001.png"]


def test_events_must_be_auto_or_poll(rig):
    folder, cam, plan, photos = rig
    with pytest.raises(SessionError, match=r"events = 'inotify': expected one of auto, poll"):
        Watcher(folder, camera_dir=cam, events="inotify")


def test_the_start_line_says_how_the_folder_is_followed(rig):
    import threading

    from vision_torsion.session.watch import watch_session

    folder, cam, plan, photos = rig
    for events, how in (("auto", "filesystem events"), ("poll", "polling every 0.05 s: polling was asked for")):
        seen = []
        stop = threading.Event()
        stop.set()  # one look, then stop
        watch_session(folder, camera_dir=cam, poll_s=0.05, stop=stop, events=events, echo=seen.append)
        assert seen[0].message.startswith(f"watching {cam} ({how}) for 10 planned images; live page: ")


class RefusingObserver:
    """A watchdog observer whose notifications cannot be set up (the inotify limit)."""

    def start(self):
        pass

    def schedule(self, *args, **kwargs):
        import errno

        raise OSError(errno.ENOSPC, "No space left on device")

    def stop(self):
        pass

    def join(self, timeout=None):
        pass


def test_the_notification_limit_reached_falls_back_to_polling(tmp_path):
    from vision_torsion.session.events import FolderEvents

    with FolderEvents(tmp_path, observer=RefusingObserver) as ev:
        assert not ev.active
        assert ev.why_polling == ("the file notifications could not be set up (No space left on device; on "
                                  "Linux, fs.inotify.max_user_watches or max_user_instances)")
        assert not ev.ensure()  # decided for good: no new attempt at every look


def test_without_watchdog_the_folder_is_polled(tmp_path):
    from vision_torsion.session.events import FolderEvents

    def missing():
        raise ImportError("No module named 'watchdog'")

    with FolderEvents(tmp_path, observer=missing) as ev:
        assert not ev.active and ev.why_polling == "the watchdog package is not installed"


def test_a_folder_on_a_network_share_is_polled(tmp_path):
    from vision_torsion.session.events import FolderEvents, network_filesystem

    share = tmp_path / "my share"
    share.mkdir()
    table = tmp_path / "mountinfo"
    escaped = str(share).replace(" ", "\\040")
    table.write_text(f"22 1 8:1 / / rw,relatime shared:1 - ext4 /dev/sda1 rw\n"
                     f"40 22 0:50 / {escaped} rw,relatime shared:9 - nfs4 server:/photos rw,vers=4.2\n")
    assert network_filesystem(tmp_path, mount_table=table) is None  # ext4: local
    assert network_filesystem(share / "sub", mount_table=table) == "nfs4"
    with FolderEvents(share, mount_table=table) as ev:
        assert ev.why_polling == (f"{share} is on a network file system (nfs4), whose notifications miss "
                                  "what another computer writes")


def sparse(path, size):
    with open(path, "wb") as fh:
        fh.truncate(size)  # no disk used; reading it whole would take `size` bytes of memory


def test_watch_sets_aside_a_file_over_the_size_limit_without_reading_it(rig):
    from vision_torsion.images import MAX_IMAGE_FILE_BYTES

    folder, cam, plan, photos = rig
    sparse(cam / "IMG_0001.png", 3 * 1024**3)
    put(cam, "IMG_0002.png", photos[plan.rows[0]["image"]])
    os.utime(cam / "IMG_0002.png", (1.8e9, 1.8e9))
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock, events="poll") as w:
        events = run(w, clock)
        assert messages(events, "ignored") == [
            f"IMG_0001.png: {3 * 1024**3} bytes, larger than an image file may be ({MAX_IMAGE_FILE_BYTES} "
            "bytes); not read, not bound"]
        # it holds nothing back, and takes no row
        assert {b.file: b.row.line for b in w.bound.values()} == {"IMG_0002.png": 2}


def test_bind_sets_aside_a_file_over_the_size_limit_without_reading_it(rig):
    from vision_torsion.images import MAX_IMAGE_FILE_BYTES
    from vision_torsion.session.bind import bind_session

    folder, cam, plan, photos = rig
    for k, row in enumerate(plan.rows[:2]):
        put(cam, f"IMG_{2 * k + 1:04d}.png", photos[row["image"]])
    sparse(cam / "IMG_0002.png", MAX_IMAGE_FILE_BYTES + 1)
    res = bind_session(folder, cam, write=False)
    assert res.ignored == (("IMG_0002.png", f"{MAX_IMAGE_FILE_BYTES + 1} bytes, larger than an image file may "
                                            f"be ({MAX_IMAGE_FILE_BYTES} bytes); not bound"),)
    assert res.binding.images == {plan.rows[0]["image"]: "IMG_0001.png", plan.rows[1]["image"]: "IMG_0003.png"}


def test_ctrl_c_ends_a_watch_on_filesystem_events_cleanly(rig):
    import signal
    import subprocess
    import sys
    from pathlib import Path

    folder, cam, plan, photos = rig
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root), "PYTHONWARNINGS": "error"}
    # as from a terminal: Ctrl-C raises KeyboardInterrupt even when this test runs where SIGINT is
    # ignored and children inherit that (a background job of a non-interactive shell, as CI may be);
    # -X faulthandler: if it ever hangs, SIGABRT makes it print every thread's stack
    start = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
             "sys.argv = ['vision-torsion'] + sys.argv[1:]; runpy.run_module('vision_torsion', run_name='__main__')")
    cmd = [sys.executable, "-X", "faulthandler", "-c", start, "watch", str(folder), "--camera-dir", str(cam),
           "--no-report"]
    with subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        try:
            assert "(filesystem events)" in proc.stdout.readline()
            write_closed(cam / "IMG_0001.png", photos[plan.rows[0]["image"]])
            assert "IMG_0001.png → line 2" in proc.stdout.readline()
            proc.send_signal(signal.SIGINT)
            try:
                out, err = proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                proc.send_signal(signal.SIGABRT)
                out, err = proc.communicate(timeout=30)
                pytest.fail(f"watch did not end within 60 s of Ctrl-C; its threads:\n{err}")
        finally:
            proc.kill()
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    assert out.startswith("stopped; run the same command again to resume\n1 of 10 planned images bound")


def test_the_live_page_and_its_stamp_change_with_each_photograph(rig):
    folder, cam, plan, photos = rig
    page, stamp = folder / "results" / "live.html", folder / "results" / "live-stamp.js"
    clock = Clock()

    def versions():
        mine = re.search(r'var mine = "(\w+)"', page.read_text()).group(1)
        return mine, re.fullmatch(r'liveStamp\("(\w+)"\);\n', stamp.read_text()).group(1)

    with Watcher(folder, camera_dir=cam, clock=clock) as w:
        w.write_page()
        first, in_stamp = versions()
        assert first == in_stamp
        put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]])
        run(w, clock, 1)
        second, in_stamp = versions()
        assert second == in_stamp != first and "IMG_0001.png" in page.read_text()


def test_a_bound_photo_replaced_by_an_over_size_file_fails_its_row(rig):
    from vision_torsion.images import MAX_IMAGE_FILE_BYTES

    folder, cam, plan, photos = rig
    put(cam, "IMG_0001.png", photos[plan.rows[0]["image"]])
    put(cam, "IMG_0002.png", photos[plan.rows[1]["image"]])
    clock = Clock()
    with Watcher(folder, camera_dir=cam, clock=clock, events="poll") as w:
        run(w, clock)
        assert w.bound[1].angle is not None
        sparse(cam / "IMG_0002.png", MAX_IMAGE_FILE_BYTES + 1)
        os.utime(cam / "IMG_0002.png", (1.8e9, 1.8e9))
        events = run(w, clock)
        assert messages(events, "replaced") == [SECOND_REPLACED]
        # the old angle is not kept for a file that is no longer that image
        assert np.isnan(w.bound[1].angle)
        assert w.bound[1].own == [f"not read: IMG_0002.png: {MAX_IMAGE_FILE_BYTES + 1} bytes, larger than an "
                                  f"image file may be ({MAX_IMAGE_FILE_BYTES} bytes)"]
        assert run(w, clock) == []  # said once


class StuckObserver:
    """An observer whose stop never returns (its reading thread blocked in read())."""

    def __init__(self):
        import threading

        self.never = threading.Event()

    def start(self):
        pass

    def schedule(self, handler, path, event_filter=None):
        return object()

    def unschedule(self, watch):
        self.never.wait()

    def stop(self):
        self.never.wait()

    def join(self, timeout=None):
        pass


def test_a_stuck_observer_never_holds_up_the_end_of_a_watch(tmp_path):
    import threading
    import time

    from vision_torsion.session.events import STOP_WAIT_S, FolderEvents

    ev = FolderEvents(tmp_path, observer=StuckObserver)
    assert ev.active

    def end():
        ev.rearm()  # drops the folder's watch first: bounded too
        ev.close()

    ending = threading.Thread(target=end, daemon=True)
    t0 = time.monotonic()
    ending.start()
    ending.join(timeout=4 * STOP_WAIT_S)
    assert not ending.is_alive(), "closing waited for an observer that never stops"
    assert time.monotonic() - t0 < 3 * STOP_WAIT_S + 1.0
