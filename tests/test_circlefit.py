"""Circle and ellipse fits on points of known geometry, and their failure messages."""

import numpy as np
import pytest

from vision_torsion.circlefit import (
    centred_ellipse,
    centred_ellipse_and_polar,
    centred_ellipse_polar,
    fit_circle,
    fit_circle_algebraic,
    fit_circle_geometric,
    fit_ellipse,
)
from vision_torsion.errors import FitError


def _noisy_circle(rng, n=200, cx=812.3, cy=455.7, r=35.2, sigma=0.02, arc=2 * np.pi):
    t = np.linspace(0, arc, n, endpoint=False)
    return cx + r * np.cos(t) + sigma * rng.standard_normal(n), cy + r * np.sin(t) + sigma * rng.standard_normal(n)


def test_geometric_fit_recovers_centre_with_honest_covariance():
    """Over 300 noisy circles the centre scatter matches the reported std within 15 %."""
    rng = np.random.default_rng(0)
    errs, stds = [], []
    for _ in range(300):
        x, y = _noisy_circle(rng)
        f = fit_circle_geometric(x, y, weights=np.full(x.size, 1 / 0.02**2))
        errs.append(f.x_px - 812.3)
        stds.append(f.centre_std_px[0])
    ratio = np.mean(stds) / np.sqrt(np.mean(np.square(errs)))
    assert 0.85 < ratio < 1.15  # 300 samples: RMS known to ~4 %


def test_geometric_beats_algebraic_on_a_partial_arc():
    """On a 90° arc the Kasa fit is biased towards a smaller circle; the geometric fit is not."""
    rng = np.random.default_rng(4)
    geo, alg = [], []
    for _ in range(100):
        x, y = _noisy_circle(rng, arc=np.pi / 2, sigma=0.3)
        geo.append(fit_circle_geometric(x, y).radius_px - 35.2)
        alg.append(fit_circle_algebraic(x, y).radius_px - 35.2)
    assert abs(np.mean(geo)) < 0.5 * abs(np.mean(alg))


def test_outliers_are_rejected():
    rng = np.random.default_rng(2)
    x, y = _noisy_circle(rng, sigma=0.01)
    x[:8] += 3.0  # a wire across part of the edge
    f = fit_circle_geometric(x, y)
    assert f.inliers[:8].sum() == 0 and f.inliers[8:].all()
    assert abs(f.x_px - 812.3) < 0.005 and abs(f.y_px - 455.7) < 0.005


def test_algebraic_fit_is_the_paper_formula():
    """The Kasa solution minimises Q = sum[(x-a)^2 + (y-b)^2 - r^2]^2: Q grows when moved."""
    rng = np.random.default_rng(5)
    x, y = _noisy_circle(rng, sigma=0.2)
    f = fit_circle_algebraic(x, y)

    def q(a, b, r):
        return np.sum(((x - a) ** 2 + (y - b) ** 2 - r**2) ** 2)

    best = q(f.x_px, f.y_px, f.radius_px)
    for d in np.eye(3) * 1e-3:
        assert q(f.x_px + d[0], f.y_px + d[1], f.radius_px + d[2]) > best
        assert q(f.x_px - d[0], f.y_px - d[1], f.radius_px - d[2]) > best


def test_ellipse_fit_recovers_axes_and_orientation():
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    th = np.deg2rad(25.0)  # 25° CCW as displayed = -25° in image axes
    a, b = 36.0, 33.0
    u, v = a * np.cos(t), b * np.sin(t)
    x = 300.2 + u * np.cos(-th) - v * np.sin(-th)
    y = 211.9 + u * np.sin(-th) + v * np.cos(-th)
    e = fit_ellipse(x, y)
    assert abs(e.x_px - 300.2) < 1e-6 and abs(e.y_px - 211.9) < 1e-6
    assert abs(e.a_px - a) < 1e-6 and abs(e.b_px - b) < 1e-6
    assert abs(e.angle_deg - 25.0) < 1e-4


def test_fit_errors():
    with pytest.raises(FitError, match="need at least 3 finite edge points, got 2"):
        fit_circle_algebraic([0, 1], [0, 1])
    with pytest.raises(FitError, match="need at least 5 finite edge points"):
        fit_circle_geometric([0, 1, 2], [0, 1, 0])
    with pytest.raises(FitError, match="x and y have different lengths"):
        fit_circle_geometric([0, 1, 2, 3, 4], [0, 1])
    with pytest.raises(FitError, match="all edge points coincide"):
        fit_circle_algebraic([1.0] * 5, [2.0] * 5)
    with pytest.raises(FitError, match="weights must be finite and not negative"):
        fit_circle_geometric(*_noisy_circle(np.random.default_rng(0), n=10), weights=[-1.0] * 10)
    with pytest.raises(FitError, match="unknown circle-fit method 'hough'"):
        fit_circle([0, 1, 2], [0, 1, 0], method="hough")
    line = np.arange(10.0)
    with pytest.raises(FitError, match="degenerate|singular"):
        fit_circle_algebraic(line, 2 * line)


def test_ellipse_on_a_short_arc_is_a_failure_not_a_huge_ellipse():
    """Issue 18: on a 20° arc of a 35 px circle the ellipse fit returned semi-axes of
    millions of px (one negative) with no error. The points fix no ellipse there: the
    normal equations are singular to machine precision, so it must fail with a reason."""
    rng = np.random.default_rng(0)
    t = np.radians(np.linspace(0.0, 20.0, 40))
    x = 300.3 + 35 * np.cos(t) + rng.normal(0, 0.02, t.size)
    y = 200.7 + 35 * np.sin(t) + rng.normal(0, 0.02, t.size)
    with pytest.raises(FitError, match="ill-conditioned .* too short an arc"):
        fit_ellipse(x, y)


@pytest.mark.parametrize("arc_deg, ratio", [(360, 1.0), (360, 0.9), (180, 1.0), (90, 1.0)])
def test_ellipse_guards_keep_well_posed_fits(arc_deg, ratio):
    """The guards refuse nothing that was right: full near-circles (θ undetermined),
    a half and a quarter arc, at image coordinates far from the origin. Tolerances:
    the noise (0.02 px) over 100-200 points for full ellipses; on a part arc the five
    ellipse parameters trade off against each other (0.6 px off on this quarter arc,
    the centre covariance says ~0.35 px), so 1 px there."""
    rng = np.random.default_rng(3)
    t = np.radians(np.linspace(0.0, arc_deg, 200 if arc_deg == 360 else 100, endpoint=arc_deg != 360))
    x = 1300.3 + 35 * np.cos(t) + rng.normal(0, 0.02, t.size)
    y = 900.7 + ratio * 35 * np.sin(t) + rng.normal(0, 0.02, t.size)
    e = fit_ellipse(x, y)
    tol = 0.01 if arc_deg == 360 else 1.0
    assert abs(e.x_px - 1300.3) < tol and abs(e.y_px - 900.7) < tol
    assert 0 < e.b_px <= e.a_px < 60


def test_centred_ellipse_gives_the_ellipse_fit_s_axis_ratio():
    """centred_ellipse (a linear fit of 1/r² in polar coordinates about a known
    centre) against the library's general ellipse fit on points of an ellipse centred
    on the origin (semi-axes 12 and 7.3 px at 25°, noise 0.01 px): the same axis
    ratio within 0.003 (the noise moves each by ~1e-3) and a distance from the curve
    at the noise; points of a teardrop (a circle with one half stretched) are far
    from any ellipse centred there, points of no ellipse at all give None."""
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 2 * np.pi, 90, endpoint=False)
    a, b, th = 12.0, 7.3, np.deg2rad(25.0)
    x = a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th) + 0.01 * rng.standard_normal(t.size)
    y = a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th) + 0.01 * rng.standard_normal(t.size)
    ratio, rms = centred_ellipse(x, y)
    general = fit_ellipse(x, y)
    assert general.b_px / general.a_px == pytest.approx(b / a, abs=0.003)
    assert ratio == pytest.approx(general.b_px / general.a_px, abs=0.003)
    assert rms < 0.03
    stretched = 10.0 * (1.0 + 0.5 * (np.sin(t) > 0) * np.sin(t))  # r(ψ): a teardrop
    _, rms_tear = centred_ellipse(stretched * np.cos(t), stretched * np.sin(t))
    assert rms_tear > 0.5
    # four points on a circle of 10 px and one 1.4 px from the centre: the fitted
    # 1/r² is negative in some directions, which no ellipse is
    assert centred_ellipse(np.array([10.0, -10.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 10.0, -10.0, 1.0])) is None


def test_centred_ellipse_and_polar_is_both_from_one_fit():
    """centred_ellipse_and_polar gives centred_ellipse's (axis ratio, RMS distance),
    or None where the points lie on no ellipse, together with centred_ellipse_polar's
    (A, B, C): the semi-axes 12 and 7.3 px at 25° are 1/√(A ∓ √(B² + C²)), the major
    axis at atan2(-C, -B)/2."""
    t = np.linspace(0.0, 2 * np.pi, 90, endpoint=False)
    a, b, th = 12.0, 7.3, np.deg2rad(25.0)
    x = a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th)
    y = a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th)
    found, (A, B, C) = centred_ellipse_and_polar(x, y)
    assert found == centred_ellipse(x, y)
    assert np.array_equal((A, B, C), centred_ellipse_polar(x, y))
    h = np.hypot(B, C)
    assert (1 / np.sqrt(A - h), 1 / np.sqrt(A + h), 0.5 * np.arctan2(-C, -B)) == pytest.approx((a, b, th))
    none_x, none_y = np.array([10.0, -10.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 10.0, -10.0, 1.0])
    found, polar = centred_ellipse_and_polar(none_x, none_y)
    assert found is None and np.array_equal(polar, centred_ellipse_polar(none_x, none_y))
