"""The live page: round ticks, no line across an unphotographed load change, loop
closure and drift, and the link to the report once the watch has ended."""

import re

import pytest

from vision_torsion.session.live import LivePoint, live_page, loop_closure, nice_ticks


@pytest.mark.parametrize(
    ("lo", "hi", "ticks"),
    [
        (-6.88, 13.8, [-5.0, 0.0, 5.0, 10.0]),  # the axis: -6.88, 3.48, 13.8 before
        (-0.396, 0.396, [-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3]),
        (1.0, 148.0, [25.0, 50.0, 75.0, 100.0, 125.0]),
        (26.69, 26.7, [26.69, 26.6925, 26.695, 26.6975, 26.7]),
        (0.0, 1e-5, [0.0, 2.5e-6, 5e-6, 7.5e-6, 1e-5]),
    ],
)
def test_round_ticks(lo, hi, ticks):
    assert nice_ticks(lo, hi) == pytest.approx(ticks)


def test_ticks_of_an_empty_range():
    assert nice_ticks(2.0, 2.0) == [2.0] and nice_ticks(float("nan"), 1.0) == []


def protocol_points(*, steps=3, cycles=1, closing_offset=None, drift_per_cycle=0.0):
    """One orientation shot by the protocol: reference, then cycles of four phases."""
    step = 0.1  # N·m per step
    seq = [("reference", 0.0)]
    for _ in range(cycles):
        seq += [("positive_unloading", steps - i) for i in range(steps + 1)]
        seq += [("negative_loading", -i) for i in range(steps + 1)]
        seq += [("negative_unloading", -steps + i) for i in range(steps + 1)]
        seq += [("positive_loading", i) for i in range(steps + 1)]
    if closing_offset is not None:
        seq.append(("closing", 0))
    pts, prev = [], float("nan")
    for n, (phase, k) in enumerate(seq, start=1):
        cycle_no = sum(1 for ph, kk in seq[:n] if ph == "positive_unloading" and kk == steps)
        torque = k * step
        # branches apart by up to 1 deg at zero torque, meeting at the extremes
        shift = (1.0 if phase in ("positive_unloading", "negative_loading") else -1.0) * (1 - abs(k) / steps)
        angle = 20.0 * torque + (0.0 if phase == "reference" else shift) + drift_per_cycle * (cycle_no - 1)
        if phase == "positive_loading" and k == steps:
            angle += drift_per_cycle  # the loop ends where the next begins
        if phase == "closing":
            angle = pts[steps + 1].angle_deg + closing_offset  # the first loop's last unloading image
        pts.append(LivePoint(n, f"IMG_{n:04d}.JPG", n + 1, 0.0, f"{phase} s{abs(k)}", torque, angle,
                             angle - prev))
        prev = angle
    return pts


def test_closure_of_loops_and_the_closing_image():
    pts = protocol_points(cycles=2, closing_offset=0.02, drift_per_cycle=0.1)
    found = loop_closure(pts)
    assert [w for w, _ in found] == ["loop 1", "loop 2", "closing − loop 1 unloaded"]
    assert [d for _, d in found] == pytest.approx([0.1, 0.1, 0.02])


def test_no_line_from_the_reference_to_the_preload():
    pts = protocol_points()
    page = live_page(title="t", points=pts, planned_torques=[p.torque_nm for p in pts], next_step=None)
    svg = page[page.index("<svg"):page.index("</svg>")]
    lines = re.findall(r'<polyline points="([^"]*)"', svg)
    # the reference alone, then the loop: the pre-load to +Tmax was not photographed
    assert len(lines) == 2 and len(lines[0].split()) == 1 and len(lines[1].split()) == len(pts) - 1


def test_closure_is_shown_and_an_open_loop_is_named():
    pts = protocol_points(cycles=1, drift_per_cycle=0.5)  # 0.5 deg: beyond 1 % of a ~8 deg span
    page = live_page(title="t", points=pts, planned_torques=[p.torque_nm for p in pts], next_step="x")
    assert "Loop closure and drift (0°)" in page and "loop 1: +0.5000° (open by more than 1 %" in page
    closed = live_page(title="t", points=protocol_points(), planned_torques=[0.0, 0.1], next_step="x")
    assert "loop 1: +0.0000° (closes)" in closed


def test_report_link_once_finished():
    pts = protocol_points()
    running = live_page(title="t", points=pts, planned_torques=[0.0, 0.1], next_step="x")
    done = live_page(title="t", points=pts, planned_torques=[0.0, 0.1], next_step=None, finished=True)
    assert 'href="report.html"' not in running and 'http-equiv="refresh"' in running
    assert 'The report: <a href="report.html">' in done and 'http-equiv="refresh"' not in done


def test_the_page_reloads_when_its_stamp_changes():
    from vision_torsion.session.live import LIVE_STAMP_NAME, stamp_script

    pts = protocol_points()
    running = live_page(title="t", points=pts, planned_torques=[0.0, 0.1], next_step="x", version="18a-b_c")
    # the stamp file is looked at with a script; a browser without scripts reloads every second
    assert 'var mine = "18a-b_c"' in running and f'e.src = "{LIVE_STAMP_NAME}?" + Date.now();' in running
    assert '<noscript><meta http-equiv="refresh" content="1"></noscript>' in running
    assert "updates as each photograph comes in" in running
    assert stamp_script("18a-b_c") == 'liveStamp("18a-b_c");\n'
    done = live_page(title="t", points=pts, planned_torques=[0.0, 0.1], next_step=None, finished=True,
                     version="18a")
    assert "<script" not in done and "refresh" not in done


def test_a_stamp_is_letters_digits_and_dashes():
    from vision_torsion.session.live import stamp_script

    with pytest.raises(ValueError, match=r"""version must be letters, digits, '-' or '_', got '1"\);alert\(1'"""):
        stamp_script('1");alert(1')
    with pytest.raises(ValueError, match="version must be letters"):
        live_page(title="t", points=[], planned_torques=[0.0], next_step="x", version="")
