"""report and demo: from a session folder to report.html, end to end on a small session."""

import json

import pandas as pd
import pytest

from vision_torsion.cli import main
from vision_torsion.report.session_report import demo_scene, report_session
from vision_torsion.synthetic.session import SessionSpec, load_session_scene, write_session_folder


def test_demo_scene_is_the_paper_session_file(scene_file):
    scene, spec = load_session_scene(scene_file("paper_session"))
    assert demo_scene() == (scene, spec)


@pytest.fixture(scope="module")
def small_session(tmp_path_factory, small_scene):
    """One orientation, four steps per phase, a 400x300 view: 18 images."""
    spec = SessionSpec(step_mass_kg=0.09, orientations_deg=(0.0,), k_u_nm_per_rad=4.4, angle_sign=-1)
    # the small view turns the markers through ±30°: keep them in the frame
    scene = small_scene.replace(markers={"distance_px": 90.0})
    return write_session_folder(scene, spec, tmp_path_factory.mktemp("s") / "session", seed=4)


def test_report_command_writes_everything(small_session, capsys):
    code = main(["report", str(small_session), "--jobs", "1"])
    assert code == 0
    out = small_session / "results"
    for name in ("measurements.csv", "summary.json", "stiffness_table.csv", "report.html"):
        assert (out / name).is_file(), name
    html = (out / "report.html").read_text()
    assert "<img" in html and "http://" not in html.split("<body", 1)[1]  # self-contained
    summary = json.loads((out / "summary.json").read_text())
    truth = pd.read_csv(small_session / "truth.csv")
    meas = pd.read_csv(out / "measurements.csv")
    merged = meas.merge(truth, on="image")
    # angles come back in the reported convention (angle_sign applied) within 0.01°
    assert (merged["angle_deg"] - merged["true_angle_deg"]).abs().max() < 0.01
    assert summary["counts"]["images"] == len(meas)
    assert "report:" in capsys.readouterr().out


def test_report_of_a_folder_without_session_exits_2(tmp_path, capsys):
    assert main(["report", str(tmp_path), "-q"]) == 2
    assert "session.toml" in capsys.readouterr().err


def test_report_session_function_reuses_the_cache(small_session):
    rep = report_session(small_session, jobs=1)
    assert rep.n_failed == 0 and rep.files.report_html.is_file()


def test_demo_reuses_its_session_renders_on_a_new_seed_and_on_force(tmp_path, monkeypatch, small_scene):
    from vision_torsion.report import session_report

    spec = SessionSpec(step_mass_kg=0.09, orientations_deg=(0.0,), k_u_nm_per_rad=4.4, angle_sign=-1)
    # the demo's scene made small (18 images) so the test takes seconds, not a minute
    scene = small_scene.replace(markers={"distance_px": 90.0})
    monkeypatch.setattr(session_report, "demo_scene", lambda: (scene, spec))
    truth = tmp_path / "session" / "truth.csv"

    def run(*args):
        assert main(["demo", str(tmp_path), "--jobs", "1", "-q", *args]) == 0
        return truth.stat().st_mtime_ns, truth.read_text()

    first = run("--seed", "3")
    assert json.loads((tmp_path / "demo.json").read_text()) == {"seed": 3}
    assert run("--seed", "3") == first  # reused: not rendered again
    forced = run("--seed", "3", "--force")
    assert forced[0] != first[0] and forced[1] == first[1]  # rendered again, the same session
    other = run("--seed", "4")
    assert other[1] != first[1]  # another seed is another session, never the old one reused
    assert (tmp_path / "session" / "results" / "report.html").is_file()
