"""The analysis' options: checked once, when the options object is made, each refusal
naming the option, its value and its range; the keywords of ``analyze_session`` and an
``AnalysisOptions`` give the same analysis."""

import json

import numpy as np
import pytest

from vision_torsion.analysis import AnalysisOptions, analyze_session
from vision_torsion.errors import AnalysisError
from vision_torsion.synthetic import simulate_measurements


@pytest.mark.parametrize("options, match", [
    (dict(n_draws=1), r"n_draws must be a whole number >= 10, got 1"),
    (dict(seed=-1), r"seed must be a whole number >= 0, got -1"),
    (dict(secant_interval=(0.8, 0.2)), r"secant_interval must be fractions 0 <= a < b <= 1 of the max torque"),
    (dict(secant_interval=(0.5, 1.5)), r"secant_interval\[1\] must be a finite number in \[0, 1\], got 1.5"),
    (dict(secant_interval=(0.5,)), r"secant_interval must be two fractions \(a, b\), got \(0.5,\)"),
    (dict(lost_motion_fractions=()), r"lost_motion_fractions must be a non-empty list of fractions in \(0, 1\)"),
    (dict(lost_motion_fractions=(0.03, 3)), r"lost_motion_fractions\[1\] must be a finite number in \(0, 1\), got 3"),
    (dict(rated_torque_nm=0), r"rated_torque_nm must be a finite number > 0 \(N·m\), got 0"),
    (dict(gear_ratio=float("nan")), r"gear_ratio must be a finite number > 0, got nan"),
    (dict(catalogue_breaks_nm=(0.3, 0.1)),
     r"catalogue_breaks_nm must be two torques, \(T1, T2\) with 0 < T1 < T2 \(N·m\), got \(0.3, 0.1\)"),
    (dict(catalogue_breaks_nm=(0.0, 0.1)), r"catalogue_breaks_nm\[0\] must be a finite number > 0 \(N·m\), got 0.0"),
    (dict(secant_interval_nm=(0.2, 0.2)), r"secant_interval_nm must be two torques, \(a, b\) with 0 <= a < b"),
])
def test_each_option_is_checked_with_its_name_value_and_range(options, match):
    with pytest.raises(AnalysisError, match=match) as info:
        AnalysisOptions(**options)
    assert info.value.reason == "bad_value"


def test_the_data_fill_in_the_max_torque_and_the_secant_interval():
    opts = AnalysisOptions(secant_interval=(0.25, 0.75)).for_data(0.4)
    assert opts.max_torque_nm == 0.4 and opts.secant_interval_nm == (0.1, 0.30000000000000004)
    assert opts.lost_motion_reference_nm == 0.4
    given = AnalysisOptions(max_torque_nm=0.5, rated_torque_nm=0.3).for_data(0.4)
    assert given.max_torque_nm == 0.5 and given.lost_motion_reference_nm == 0.3


def test_options_are_frozen_and_default_the_torque_model_from_the_rig():
    rig = dict(step_mass_kg=0.02, mass_std_kg=1e-4, gravity_m_per_s2=9.81, arm_radius_m=0.05)
    assert AnalysisOptions().torque_correlation == "level"
    assert AnalysisOptions(rig=rig).torque_correlation == "pieces"
    assert not AnalysisOptions(torque_model_declared=False).torque_modelled
    with pytest.raises(AttributeError):
        AnalysisOptions().n_draws = 5


def test_an_options_object_gives_the_same_analysis_as_the_keywords():
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), rng=np.random.default_rng(2))
    by_keywords = analyze_session(df, n_draws=20, seed=4, rated_torque_nm=0.5)
    by_object = analyze_session(df, options=AnalysisOptions(n_draws=20, seed=4, rated_torque_nm=0.5))
    # as JSON text: NaN (a withheld figure) equals itself there
    assert json.dumps(by_keywords.to_dict(), default=str) == json.dumps(by_object.to_dict(), default=str)
    with pytest.raises(TypeError, match="either as options= or as keywords, not both"):
        analyze_session(df, options=AnalysisOptions(), n_draws=20)
