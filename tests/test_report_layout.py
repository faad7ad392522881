"""How the report looks and prints (issue 14, item 8): value axes of any sign, no
log axis with a single tick label, titles in words, version/date/metadata at the top."""

import re

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from vision_torsion import __version__
from vision_torsion.analysis import analyze_session
from vision_torsion.report import figures as fig
from vision_torsion.report import write_report
from vision_torsion.synthetic import simulate_measurements


@pytest.fixture(scope="module")
def analysed():
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0, 60), rng=np.random.default_rng(8))
    return df, analyze_session(df, n_draws=30, fit_bouc_wen=False)


def _tick_labels(figure):
    FigureCanvasAgg(figure).draw()
    ax = figure.axes[0]
    lo, hi = ax.get_ylim()
    return [t.get_text() for t in ax.yaxis.get_majorticklabels()
            if t.get_text() and lo <= t.get_position()[1] <= hi]


def test_value_axis_is_linear_unless_positive_over_a_decade():
    assert fig.value_scale([0.3, 4.5]) == "log"
    assert fig.value_scale([0.3, 2.0]) == "linear"
    assert fig.value_scale([-4.4, -0.3]) == "linear"       # a wrong angle sign
    assert fig.value_scale([np.nan, 1.0, np.inf]) == "linear"


def test_phase_stiffness_chart_has_several_tick_labels(analysed):
    # The demo's 0.3 / 4.4 N·m/rad phases used to show one label ("1.0") on a log axis.
    _, a = analysed
    chart = fig.phase_stiffness_chart(a)
    assert len(_tick_labels(chart)) >= 3
    assert "N·m/rad" in chart.axes[0].get_title()


def test_inverted_angle_sign_still_writes_the_report(analysed, tmp_path):
    # Negated angles give negative stiffnesses: drawn on a linear axis, no traceback
    # from a log-scaled axis; the report is written.
    df, _ = analysed
    flipped = df.assign(angle_deg=-df["angle_deg"])
    a = analyze_session(flipped, n_draws=30, fit_bouc_wen=False)
    files = write_report(flipped, a, conditions={"angle sign": 1}, out_dir=tmp_path)
    assert files.report_html.stat().st_size > 0
    assert all(b"<svg" in p.read_bytes()[:1000] for p in files.figures)


def test_a_figure_that_cannot_be_drawn_is_a_figure_saying_so(caplog):
    def broken(_):
        raise ValueError("Data cannot be log-scaled")

    svg = fig.safe_svg(broken, None)
    assert b"<svg" in svg[:1000]
    assert "could not be drawn: Data cannot be log-scaled" in caplog.text


def test_titles_are_words_with_units(analysed):
    _, a = analysed
    overlay = fig.loops_overlay(a).axes[0].get_title()
    detail = fig.loop_detail(a, 0.0).axes[0].get_title()
    assert "(N·m)" in overlay and "(deg)" in overlay and "(N·m)" in detail
    chart = fig.orientation_chart(a).axes[0]
    assert "(%)" in chart.get_title() and "(%)" in chart.get_ylabel()
    entries = [t.get_text() for t in chart.get_legend().get_texts()]
    assert entries and not any("_" in t for t in entries)
    assert any("N·m/rad" in t for t in entries)          # each figure's session mean with its unit
    residuals = fig.fit_residuals(a).axes[0]
    assert "(deg)" in residuals.get_title() and "(deg)" in residuals.get_ylabel()


def test_header_has_version_date_and_present_metadata(analysed, tmp_path):
    df, a = analysed
    meta = {"gear": "CSF-17-100", "serial": "A123", "operator": "", "temperature_c": 21.5, "notes": None}
    files = write_report(df, a, conditions={}, out_dir=tmp_path, metadata=meta)
    page = files.report_html.read_text()
    head = page[:page.index("<h2>")]
    assert f"vision-torsion {__version__}" in head
    assert re.search(r"report date:</b> \d{4}-\d\d-\d\d \d\d:\d\d UTC", head)
    assert "CSF-17-100" in head and "A123" in head and "temperature c:</b> 21.5" in head
    assert "operator" not in head and "notes" not in head   # blank or missing: not shown


def test_print_rules_unclip_scrolling_tables(analysed, tmp_path):
    # On paper nothing scrolls: the print rules lift the screen's scroll box.
    df, a = analysed
    page = write_report(df, a, conditions={}, out_dir=tmp_path).report_html.read_text()
    css = page[page.index("@media print"):page.index("</style>")]
    assert ".scroll{max-height:none;overflow:visible" in css
    assert "@page{size:A4" in page and "break-inside:avoid" in css


def test_session_metadata_from_gear_and_test_tables():
    # What session.toml's optional [gear]/[test] tables give: the entries present, per table
    # (the report's header shows them; summary.json keeps them under "gear" and "test").
    from vision_torsion.report.analyze import test_metadata as metadata_of
    from vision_torsion.session.config import config_from_dict

    base = {"rig": {"arm_radius_m": 0.05, "mass_std_kg": 1e-4},
            "protocol": {"orientations_deg": [0], "max_torque_nm": 0.36, "step_mass_kg": 0.02}}
    cfg = config_from_dict({**base, "gear": {"name": "CSF-17-100", "rated_torque_nm": 24.0},
                            "test": {"operator": "M. Li", "temperature_c": 21.5, "notes": ""}})
    assert metadata_of(cfg) == {"gear": {"name": "CSF-17-100", "rated_torque_nm": 24.0},
                                "test": {"operator": "M. Li", "temperature_c": 21.5, "notes": ""}}
    assert metadata_of(config_from_dict(base)) == {}
