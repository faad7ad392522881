"""plan_session and the `plan` command: protocol order, file names, round trip."""

import argparse
import logging

import pytest

from vision_torsion.cli import plan as plan_cli
from vision_torsion.errors import SessionError
from vision_torsion.session import load_session, plan_config, plan_session
from vision_torsion.session.torque import couple_torque

#: plan_session's own options; the other keywords are plan_config's
PLAN_OPTIONS = ("image_suffix", "overwrite", "preconditioning_cycles", "closing", "pdf")


def plan(folder, **kw):
    args = dict(max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05)
    args.update(kw)
    options = {k: args.pop(k) for k in PLAN_OPTIONS if k in args}
    return plan_session(plan_config(**args), folder, **options)


def test_protocol_order_and_counts(tmp_path):
    p = plan(tmp_path, orientations_deg=(0, 60), cycles=2)
    n = p.steps_per_phase
    assert n == 18  # 0.36 / (2 * 0.02 * 9.81 * 0.05) = 18.35 -> 18 (never above the request)
    assert not p.exact and p.max_torque_nm == pytest.approx(0.35316, abs=1e-12)
    per_orientation = 1 + 1 + 4 * n * 2
    assert len(p.rows) == 2 * per_orientation
    o0 = p.rows[:per_orientation]
    assert o0[0]["phase"] == "reference" and o0[0]["mass_kg"] == "0"
    # cycle 1 starts at +Tmax (step 0 after the pre-load), then one step mass per image
    assert [(r["phase"], r["step"], r["mass_kg"]) for r in o0[1:4]] == [
        ("positive_unloading", "0", "0.36"), ("positive_unloading", "1", "0.34"),
        ("positive_unloading", "2", "0.32")]
    phases = [r["phase"] for r in o0[1:]]
    firsts = [phases.index(ph) for ph in ("positive_unloading", "negative_loading",
                                          "negative_unloading", "positive_loading")]
    assert firsts == sorted(firsts)
    # every load state is photographed once: cycle 2 has no step 0
    cycle2 = [r for r in o0 if r["cycle"] == "2"]
    assert len(cycle2) == 4 * n and min(int(r["step"]) for r in cycle2) == 1
    assert o0[-1]["phase"] == "positive_loading" and o0[-1]["mass_kg"] == "0.36"
    assert p.rows[per_orientation]["orientation_deg"] == "60"


def test_file_names(tmp_path):
    p = plan(tmp_path, orientations_deg=(60, 22.5))
    names = [r["image"] for r in p.rows]
    assert "images/o060_c1_03_negative_loading_s02.png" in names
    assert "images/o22p5_c1_01_reference_s00.png" in names
    assert len(set(names)) == len(names)


def test_exact_maximum_is_kept(tmp_path):
    p = plan(tmp_path, max_torque_nm=0.0981 * 3.6, step_mass_kg=0.02, orientations_deg=(0,))
    assert p.exact and p.steps_per_phase == 18


def test_snapping_is_logged(tmp_path, caplog):
    with caplog.at_level(logging.WARNING, logger="vision_torsion.session.plan"):
        plan(tmp_path)
    assert "not a whole number of 0.02 kg steps; planned 18 steps = 0.35316 N·m" in caplog.text


def test_plan_then_load_round_trip(tmp_path):
    p = plan(tmp_path, orientations_deg=(0, 120), cycles=3, mass_tolerance_kg=2e-4,
             friction_torque_std_nm=1e-4, polarity="bright", radius_range=(4, 20),
             angle_sign=-1)
    s = load_session(tmp_path, check_files=False)
    assert s.config == p.config
    assert s.config.markers.polarity == "bright" and s.config.angle_sign == -1
    assert [r.image for r in s.manifest.rows] == [r["image"] for r in p.rows]
    top = s.manifest.rows[1]
    assert s.torque(top).torque_nm == pytest.approx(p.max_torque_nm, rel=1e-12)
    assert s.config.protocol.max_torque_nm == p.max_torque_nm == 0.35316


def test_capture_sheet(tmp_path):
    plan(tmp_path, orientations_deg=(0,))
    sheet = (tmp_path / "capture_sheet.md").read_text()
    assert "requested 0.36 N·m is not a whole number of steps; snapped down" in sheet
    step = couple_torque(0.1, "negative_loading", load_session(
        tmp_path, check_files=False).config.rig).torque_nm
    assert f"{step:+.5f}" == "-0.09810"
    assert ("| negative_loading | 5 | empty | 100 g (5 × 20 g) | -0.09810 | "
            "`images/o000_c1_03_negative_loading_s05.png` |") in sheet
    assert "add 20 g to each + pan 18 times" in sheet


def test_refuses_to_overwrite(tmp_path):
    plan(tmp_path)
    with pytest.raises(SessionError, match=r"already holds a session \(session\.toml, "
                       r"manifest\.csv\)"):
        plan(tmp_path)
    plan(tmp_path, overwrite=True, cycles=2)


@pytest.mark.parametrize("kw, message", [
    (dict(max_torque_nm=0.01), r"max_torque_nm 0\.01 is less than one step"),
    (dict(arm_radius_m=0), r"rig\.arm_radius_m: must be a finite number > 0"),
    (dict(cycles=0), r"protocol\.cycles: must be a whole number >= 1"),
    (dict(image_suffix=".gif"), r"image_suffix '\.gif' is not an image type"),
])
def test_invalid_parameters(tmp_path, kw, message):
    with pytest.raises(SessionError, match=message):
        plan(tmp_path, **kw)
    assert not (tmp_path / "session.toml").exists()


def parser():
    p = argparse.ArgumentParser(prog="vision-torsion")
    plan_cli.register(p.add_subparsers(dest="command"))
    return p


def test_cli_plan(tmp_path, capsys):
    args = parser().parse_args(["plan", str(tmp_path / "s"), "--max-torque", "0.36",
                                "--step-mass", "0.02", "--arm-radius", "0.05",
                                "--orientations", "0", "90", "--cycles", "2", "--no-pdf"])
    assert args.func(args) == 0
    s = load_session(tmp_path / "s", check_files=False)
    assert s.config.protocol.orientations_deg == (0.0, 90.0)
    assert s.config.protocol.cycles == 2
    # 2 orientations x (reference + step 0 + 4 phases x 18 steps x 2 cycles) = 292
    assert "292 images in 2 orientations, 18 steps per phase" in capsys.readouterr().out


def test_cli_plan_help(capsys):
    with pytest.raises(SystemExit) as info:
        parser().parse_args(["plan", "--help"])
    assert info.value.code == 0
    assert "--max-torque NM" in capsys.readouterr().out


# -- issue 15: --steps, nearest maxima, preconditioning, closing, the HTML sheet ------


def test_steps_instead_of_max_torque(tmp_path):
    p = plan_session(plan_config(steps=5, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0,)), tmp_path)
    assert p.steps_per_phase == 5 and p.exact
    assert p.max_torque_nm == pytest.approx(5 * 0.01962, rel=1e-12)


@pytest.mark.parametrize("kw, message", [
    (dict(), r"give either max_torque_nm or steps"),
    (dict(max_torque_nm=0.36, steps=3), r"give either max_torque_nm or steps"),
    (dict(steps=0), r"steps must be a whole number >= 1, got 0"),
    (dict(steps=3, preconditioning_cycles=-1), r"preconditioning_cycles must be a whole number >= 0"),
])
def test_plan_size_messages(tmp_path, kw, message):
    with pytest.raises(SessionError, match=message):
        plan(tmp_path, max_torque_nm=kw.pop("max_torque_nm", None), **kw)


def test_nearest_achievable_maxima(tmp_path, capsys):
    # the paper's 100 g steps at r = 0.05 m: 0.0981 N·m per step; 0.36 N·m is 3.67 steps
    p = plan(tmp_path / "a", step_mass_kg=0.1, orientations_deg=(0,))
    assert p.steps_per_phase == 3 and p.nearest_max_torques_nm == (0.2943, 0.3924)
    args = parser().parse_args(["plan", str(tmp_path / "b"), "--max-torque", "0.36", "--step-mass",
                                "0.1", "--arm-radius", "0.05", "--no-pdf"])
    args.func(args)
    assert ("(requested 0.36 N·m is not a whole number of steps; the nearest achievable maxima are "
            "0.29430 N·m with 3 steps and 0.39240 N·m with 4; or give --steps)") in capsys.readouterr().out


def test_closing_image_per_orientation(tmp_path):
    p = plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0, 60),
                                 cycles=2), tmp_path, closing=True)
    closing = [r for r in p.rows if r["phase"] == "closing"]
    assert [(r["orientation_deg"], r["cycle"], r["mass_kg"]) for r in closing] == [("0", "2", "0"), ("60", "2", "0")]
    per = len(p.rows) // 2
    assert p.rows[per - 1]["phase"] == "closing" and p.rows[per - 2]["phase"] == "positive_loading"
    s = load_session(tmp_path, check_files=False)
    assert s.torque(s.manifest.rows[per - 1]).torque_nm == 0.0


def test_html_capture_sheet(tmp_path):
    plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0, 60),
                             angle_sign=-1, header={"gear": "CSF-20-100", "operator": "A. Tester"}),
                 tmp_path, preconditioning_cycles=2, closing=True)
    page = (tmp_path / "capture_sheet.html").read_text()
    assert "<td>CSF-20-100</td>" in page and "<td>A. Tester</td>" in page
    assert "<th>Serial number</th><td></td>" in page  # a blank line to fill in
    assert page.count("<section>") == 2  # one per orientation, each on its own page
    assert "loading them turns the disk, and the line from one marker to the other, <b>clockwise</b>" in page
    assert "angle_sign = -1" in page and "positive torque turns it\n clockwise" in page
    assert page.count("preconditioning, no photographs: load to +0.03924 N·m and −0.03924 N·m 2 time(s)") == 2
    assert page.count("unload to zero step by step, no photographs") == 2


def test_pdf_capture_sheet_where_chromium_is(tmp_path):
    from vision_torsion.session.sheet import find_chromium

    if find_chromium() is None:
        pytest.skip("no Chromium on this machine")
    plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0,)), tmp_path, pdf=True)
    assert (tmp_path / "capture_sheet.pdf").read_bytes().startswith(b"%PDF")


# -- issue 15: lost-motion levels at ±3 % and ±4 % of a rated torque ------------------


def test_rated_torque_levels_are_steps_of_every_phase(tmp_path):
    # 20 g at r = 0.05 m: 0.01962 N·m per piece; T_R = 6 N·m: 3 % = 0.18 -> 9 pieces, 4 % = 0.24 -> 12
    p = plan_session(plan_config(steps=20, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0, 60),
                                 cycles=2, rated_torque_nm=6.0), tmp_path)
    assert [(lv.fraction, lv.pieces) for lv in p.lost_motion_levels] == [(0.03, 9), (0.04, 12)]
    assert [lv.torque_nm for lv in p.lost_motion_levels] == [pytest.approx(0.17658), pytest.approx(0.23544)]
    assert p.lost_motion_levels[0].achieved_fraction == pytest.approx(0.02943)
    s = load_session(tmp_path, check_files=False)  # the mass checks accept the plan
    assert s.config.gear.rated_torque_nm == 6.0  # recorded where the analysis reads it
    for orientation in ("0", "60"):
        for cycle in ("1", "2"):
            torques = [s.torque(r).torque_nm for r in s.manifest.rows
                       if r.orientation_deg == float(orientation) and r.cycle == int(cycle)
                       and r.phase != "reference"]
            for lv in p.lost_motion_levels:  # +x and -x, each on both branches of the loop
                assert sum(t == pytest.approx(lv.torque_nm) for t in torques) == 2
                assert sum(t == pytest.approx(-lv.torque_nm) for t in torques) == 2
    sheet = (tmp_path / "capture_sheet.md").read_text()
    assert ("±3 % → 9 × 20 g per pan = ±0.17658 N·m (2.94 % of T_R); "
            "±4 % → 12 × 20 g per pan = ±0.23544 N·m (3.92 % of T_R)") in sheet
    assert "| -0.17658 (−3 % T_R) | `images/o000_c1_03_negative_loading_s09.png` |" in sheet
    assert "+0.23544 <b>(+4 % T_R)</b>" in (tmp_path / "capture_sheet.html").read_text()


def test_no_rated_torque_no_levels(tmp_path):
    p = plan(tmp_path, orientations_deg=(0,))
    assert p.lost_motion_levels == () and "T_R" not in (tmp_path / "capture_sheet.md").read_text()
    assert load_session(tmp_path, check_files=False).config.gear.rated_torque_nm is None


@pytest.mark.parametrize("kw, message", [
    (dict(rated_torque_nm=0.36),  # 3 % = 0.0108 N·m is 0.55 pieces -> 1 piece = 5.45 %
     r"level ±3 % of the rated torque 0\.36 N·m \(±0\.0108 N·m\): the nearest whole number, 1 piece\(s\) "
     r"of 0\.02 kg per pan, gives ±0\.01962 N·m = 5\.45 % of the rated torque, 82 % off the level \(more "
     r"than the 25 % allowed\); a step mass of 0\.00367 kg \(3\.67 g, 1 % of the rated torque per piece\)"),
    (dict(rated_torque_nm=0.2),  # 3 % = 0.006 N·m is 0.31 pieces
     r"level ±3 % of the rated torque 0\.2 N·m \(±0\.006 N·m\) is 0\.306 pieces .* rounds to 0 pieces; "
     r"a step mass of 0\.002039 kg"),
    (dict(rated_torque_nm=10.0),  # 3 % = 0.3 N·m is 15.3 pieces > 10
     r"level ±3 % .* needs 15 pieces of 0\.02 kg per pan, more than the 10 the protocol loads"),
    (dict(rated_torque_nm=1.4),  # 3 % = 2.14 -> 2, 4 % = 2.85 -> 3: distinct, allowed
     None),
    (dict(rated_torque_nm=1.2),  # 3 % = 1.83 -> 2, 4 % = 2.45 -> 2 (18 % off): the same pieces
     r"level ±4 % .* is realised by the same 2 piece\(s\) of 0\.02 kg per pan as the level ±3 %"),
    (dict(rated_torque_nm=-1), r"gear\.rated_torque_nm: must be a finite number > 0 \(N·m\), got -1"),
])
def test_rated_torque_messages(tmp_path, kw, message):
    args = dict(steps=10, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0,), **kw)
    if message is None:
        assert len(plan_session(plan_config(**args), tmp_path).lost_motion_levels) == 2
        return
    with pytest.raises(SessionError, match=message):
        plan_session(plan_config(**args), tmp_path)
    assert not (tmp_path / "session.toml").exists()


def test_cli_rated_torque(tmp_path, capsys):
    args = parser().parse_args(["plan", str(tmp_path / "s"), "--steps", "20", "--step-mass", "0.02",
                                "--arm-radius", "0.05", "--orientations", "0", "--rated-torque", "6",
                                "--no-pdf"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "Rated torque T_R = 6 N·m (session.toml: [gear] rated_torque_nm)" in out
    assert "±4 % → 12 × 20 g per pan = ±0.23544 N·m (3.92 % of T_R)" in out


def test_capture_sheet_pages_carry_their_head_and_a_camera_file_column(tmp_path):
    import re

    plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0, 60),
                             header={"gear": "CSF-20-100", "serial": "S/N 9"}),
                 tmp_path, preconditioning_cycles=1, closing=True, pdf=False)
    page = (tmp_path / "capture_sheet.html").read_text()
    heads = re.findall(r"<thead>(.*?)</thead>", page, flags=re.S)
    assert len(heads) == 2 and "Orientation 0° — CSF-20-100, S/N 9" in heads[0] and "Orientation 60°" in heads[1]
    assert all("camera file no.</th>" in h for h in heads)
    bodies = re.findall(r"<tbody>(.*?)</tbody>", page, flags=re.S)
    for body in bodies:  # every row fills the ten columns (one spanning five)
        for row in re.findall(r"<tr[^>]*>(.*?)</tr>", body, flags=re.S):
            cells = re.findall(r"<td(?: colspan=\"(\d+)\")?[^>]*>", row)
            assert sum(int(c) if c else 1 for c in cells) == 10, row
    assert 'counter(page) " of " counter(pages)' in page and 'content: "Capture sheet — CSF-20-100, S/N 9"' in page


def test_printed_capture_sheet_repeats_the_head_and_numbers_every_page(tmp_path):
    import shutil
    import subprocess

    from vision_torsion.session.sheet import find_chromium

    if find_chromium() is None or shutil.which("pdftotext") is None:
        pytest.skip("no Chromium or pdftotext on this machine")
    plan_session(plan_config(steps=18, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0,),
                             header={"gear": "CSF-20-100"}), tmp_path, pdf=True)
    text = subprocess.run(["pdftotext", "-layout", str(tmp_path / "capture_sheet.pdf"), "-"], capture_output=True,
                          text=True, check=True).stdout
    pages = [p for p in text.split("\f") if p.strip()]
    assert len(pages) >= 3  # the header page and a 74-row orientation over two pages
    for number, p in enumerate(pages, start=1):
        assert f"page {number} of {len(pages)}" in p
        if number > 1:  # every page of the orientation: its title and the column names
            assert "Orientation 0° — CSF-20-100" in p and "save as" in p and "camera" in p


def test_a_refused_plan_leaves_no_folder_behind(tmp_path, capsys):
    from vision_torsion.cli import main

    out = tmp_path / "new_session"
    assert main(["plan", str(out), "--max-torque", "1", "--step-mass", "1e-9", "--arm-radius", "0.05"]) == 2
    assert "error:" in capsys.readouterr().err
    assert not out.exists()


# -- issue 26: plan_session(config, out_dir); session.toml's format unchanged --------


#: A session.toml as `vision-torsion demo` wrote it before the rig became a TorqueRig
#: (main at ae3a2cc): sessions planned then must load, and be written back unchanged.
EARLIER_SESSION_TOML = """\
format_version = 1
angle_sign = -1

[rig]
arm_radius_m = 0.05
gravity_m_per_s2 = 9.81
mass_tolerance_kg = 0.0001
friction_torque_std_nm = 0.0
arm_radius_std_m = 0.0
gravity_std_m_per_s2 = 0.0

[markers]
polarity = "dark"
fit = "pixels"
pair = "largest"

[protocol]
orientations_deg = [
    0.0,
    60.0,
    120.0,
    180.0,
    240.0,
    300.0,
]
max_torque_nm = 0.35316
step_mass_kg = 0.02
cycles = 1

[gear]
name = "paper-demo-gear (synthetic)"
serial = "DEMO-0"
t1_nm = 0.15
t2_nm = 0.3

[test]
operator = "vision-torsion demo"
date = "2026-11-27"

[spec]
k1_min_nm_per_rad = 0.28
k2_min_nm_per_rad = 4.0
hysteresis_loss_max_arcmin = 1800.0
"""


def test_an_earlier_session_toml_loads_and_plans_the_same_session(tmp_path):
    from vision_torsion.session.config import load_config, write_config

    (tmp_path / "old.toml").write_text(EARLIER_SESSION_TOML)
    config = load_config(tmp_path / "old.toml")
    assert config.rig.step_mass_kg == 0.02 and config.rig.mass_tolerance_kg == 1e-4
    assert config.rig.step_torque_nm == pytest.approx(0.01962, rel=1e-12)
    write_config(tmp_path / "again.toml", config)
    assert (tmp_path / "again.toml").read_text() == EARLIER_SESSION_TOML
    # planning the loaded configuration again writes the same session.toml
    p = plan_session(config, tmp_path / "s")
    assert p.steps_per_phase == 18 and p.exact and p.header == {"gear": "paper-demo-gear (synthetic)",
                                                                "serial": "DEMO-0", "operator": "vision-torsion demo",
                                                                "date": "2026-11-27"}
    assert (tmp_path / "s" / "session.toml").read_text().endswith(EARLIER_SESSION_TOML)


def test_plan_session_checks_the_configuration_it_is_given(tmp_path):
    from dataclasses import replace

    with pytest.raises(SessionError, match=r"plan_session: config must be a SessionConfig \(see plan_config\), "
                                           r"got dict"):
        plan_session({"rig": {}}, tmp_path)
    config = plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05)
    bad = replace(config, protocol=replace(config.protocol, cycles=0))  # built by hand, not read from a file
    with pytest.raises(SessionError, match=r"plan_session: 1 problem\(s\)\n  protocol\.cycles: must be a whole "
                                           r"number >= 1"):
        plan_session(bad, tmp_path)
    assert not any(tmp_path.iterdir())
