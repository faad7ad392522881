"""Progress: a bar on a terminal, plain lines in a log or a pipe, nothing with --quiet."""

import io

from helpers import make_session

from vision_torsion import progress
from vision_torsion.cli import main
from vision_torsion.progress import LineProgress, progress_bar, track


class Clock:
    def __init__(self, step):
        self.t, self.step = 0.0, step

    def __call__(self):
        self.t += self.step
        return self.t


def test_lines_at_most_every_interval_and_a_last_one():
    out = io.StringIO()
    bar = LineProgress(100, desc="measuring", stream=out, interval_s=5.0, clock=Clock(1.0))
    for _ in range(100):
        bar.update()
    bar.close()
    lines = out.getvalue().splitlines()
    # one clock tick per update: a line every 5 items, then the last line
    assert len(lines) == 100 // 5 + 1
    assert lines[0] == "measuring: 5/100 images (5 %), 5 s, about 1 min 35 s left"
    assert lines[-1] == "measuring: done, 100 images in 1 min 41 s"


def test_short_work_prints_nothing():
    out = io.StringIO()
    with LineProgress(3, desc="rendering", stream=out, interval_s=5.0, clock=Clock(0.1)) as bar:
        for _ in range(3):
            bar.update()
    assert out.getvalue() == ""


def test_unknown_total():
    out = io.StringIO()
    bar = LineProgress(None, desc="reading", unit="file", stream=out, interval_s=1.0, clock=Clock(1.0))
    bar.update()
    assert out.getvalue() == "reading: 1 file, 1 s\n"


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_bar_on_a_terminal_lines_elsewhere_nothing_when_disabled():
    from tqdm import tqdm

    assert isinstance(progress_bar(3, desc="x", stream=Terminal()), tqdm)
    assert isinstance(progress_bar(3, desc="x", stream=io.StringIO()), LineProgress)
    quiet = io.StringIO()
    for _ in track(range(3), desc="x", enabled=False, stream=quiet):
        pass
    assert quiet.getvalue() == ""


def test_track_yields_every_item_and_closes():
    out = io.StringIO()
    items = list(track(["a", "b"], desc="x", stream=out))
    assert items == ["a", "b"]


def test_a_command_in_a_pipe_prints_progress_lines(tmp_path, capsys, monkeypatch):
    folder = tmp_path / "session"
    make_session(folder, orientations=(0,))
    monkeypatch.setattr(progress, "PROGRESS_INTERVAL_S", 0.0)  # a line per image
    assert main(["process", str(folder), "--jobs", "1"]) == 0
    err = capsys.readouterr().err  # capsys is not a terminal: lines, not a bar
    assert "\r" not in err and "measuring: 1/" in err and "measuring: done," in err
    assert main(["-q", "process", str(folder), "--jobs", "1", "-o", str(tmp_path / "q")]) == 0
    assert "measuring" not in capsys.readouterr().err
