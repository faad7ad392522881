"""Typed errors: every decision is taken from the error's type and ``reason`` code,
never from its message text (which is for people, and may be reworded)."""

import pickle

import numpy as np
import pytest

from vision_torsion import errors
from vision_torsion.detect import Blob
from vision_torsion.errors import AnalysisError, FitError, MeasurementsError, RecordError, VisionTorsionError
from vision_torsion.markers import fit_marker
from vision_torsion.stiffness.curve import fit_loading_branch


def test_every_error_has_a_stable_default_reason():
    classes = [getattr(errors, name) for name in errors.__all__]
    codes = [cls.reason for cls in classes]
    assert all(isinstance(c, str) and c.isidentifier() for c in codes)
    assert len(set(codes)) == len(codes)  # one code per class


def test_reason_can_be_given_and_survives_pickling():
    # worker processes send their errors back pickled
    exc = FitError("marker edge has too little contrast", reason="low_contrast")
    back = pickle.loads(pickle.dumps(exc))
    assert type(back) is FitError and back.reason == "low_contrast" and str(back) == str(exc)
    assert pickle.loads(pickle.dumps(FitError("x"))).reason == "fit_failed"


def test_measurements_error_keeps_both_documented_families():
    exc = MeasurementsError("measurements.csv, line 5: ...")
    assert isinstance(exc, AnalysisError) and isinstance(exc, RecordError)
    assert isinstance(exc, VisionTorsionError) and exc.reason == "bad_measurements"


def test_low_contrast_status_comes_from_the_reason_code():
    """A flat patch: the start finds no contrast; the status is ``low_contrast``
    because the error says so by its code (the message is not read)."""
    image = np.full((80, 90), 120.0, np.float32)
    blob = Blob(x=44.3, y=39.6, radius=10.0, elongation=1.0, fill=1.0, touches_border=False)
    for fit in ("pixels", "geometric"):
        marker = fit_marker(image, blob, fit=fit)
        assert marker.status == "low_contrast", fit


def test_not_monotonic_branch_fit_has_its_code():
    # a loading branch whose torque falls and rises again cannot give K(T) > 0
    theta = np.linspace(0.0, 0.002, 200)
    torque = np.sin(theta / 0.002 * 3 * np.pi)
    with pytest.raises(AnalysisError, match="not monotonic") as info:
        fit_loading_branch(theta, torque, order=5)
    assert info.value.reason == "not_monotonic"


def test_cli_failure_line_follows_the_status_not_the_wording():
    from vision_torsion.cli import failure_line

    assert failure_line("a.png", "residual 3x the others", status="suspect") == "a.png: residual 3x the others"
    assert (
        failure_line("a.png", "suspect: worded like one", status="failed") == "failed: a.png: suspect: worded like one"
    )
    assert failure_line("a.png", "a.png: no markers") == "failed: a.png: no markers"
    assert failure_line("a.png", "no marker at dot(s) 5", status="marker_missing") == \
        "marker_missing: a.png: no marker at dot(s) 5"
