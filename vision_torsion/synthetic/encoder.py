"""Synthetic torque-angle records with known backlash, stiffness law and noise.

Truth for every step of the stiffness analysis. The gear follows a meshing-teeth
stiffness law K(T) = Ks·n(T) (:class:`SaturatingStiffness`), has a backlash dead zone
of known width and position where the torque is zero, and a friction hysteresis
loop (unloading lies at larger twist than loading at the same torque, by
``hysteresis_deg·sin(pi·|T|/T_max)``, which vanishes at both ends so it neither
moves the dead zone nor the turning points).

:func:`synthetic_encoder_record` drives the input at constant speed through
``cycles`` full cycles (positive loading, positive unloading, through the dead zone,
negative loading, negative unloading, back to the start), samples at a fixed rate,
quantises the input to whole pulses and adds white Gaussian torque-sensor noise. The
drive position includes the torque sensor's own twist T/K_sensor, so the analysis
must remove it. :func:`synthetic_measurements` gives the camera rig's step table.

All randomness comes from ``np.random.default_rng(seed)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import SceneError
from ..stiffness.records import MEASUREMENT_COLUMNS
from ..stiffness.rig import RigConstants
from ..validate import check_number

__all__ = [
    "SaturatingStiffness",
    "stiffening_law",
    "SyntheticRecord",
    "synthetic_encoder_record",
    "realistic_encoder_record",
    "synthetic_measurements",
]


@dataclass(frozen=True)
class SaturatingStiffness:
    """Stiffness law K(T) = Ks·n(T) with n(T) = n0 + (n_max − n0)·(1 − exp(−|T|/T0)).

    The number of effective meshing tooth pairs rises quickly at small torque and
    saturates, as in the stiffness paper (about 37 pairs at 10 N·m, 50 at 30 N·m,
    K ≈ 1.5e4 N·m/rad at 18 N·m with the defaults).

    Parameters
    ----------
    tooth_stiffness_nm_per_rad : float
        Ks, N·m/rad per effective tooth pair.
    pairs_at_zero, pairs_max : float
        n0 and n_max, tooth pairs (0 < n0 < n_max).
    torque_scale_nm : float
        T0, N·m.

    Examples
    --------
    >>> law = SaturatingStiffness()
    >>> round(float(law.pairs(10.0)), 1), round(float(law.pairs(30.0)), 1)
    (37.3, 49.1)
    """

    tooth_stiffness_nm_per_rad: float = 330.0
    pairs_at_zero: float = 2.0
    pairs_max: float = 50.0
    torque_scale_nm: float = 7.5

    def __post_init__(self):
        if not (self.tooth_stiffness_nm_per_rad > 0 and self.torque_scale_nm > 0
                and 0 < self.pairs_at_zero < self.pairs_max):
            raise SceneError(f"invalid stiffness law {self!r}: need Ks > 0, T0 > 0, 0 < n0 < n_max")

    def pairs(self, torque_nm):
        """Effective meshing tooth pairs n(T) at torque T (N·m); even in T."""
        x = np.abs(np.asarray(torque_nm, dtype=float)) / self.torque_scale_nm
        return self.pairs_at_zero + (self.pairs_max - self.pairs_at_zero) * -np.expm1(-x)

    def stiffness(self, torque_nm):
        """K(T) = Ks·n(T), N·m/rad."""
        return self.tooth_stiffness_nm_per_rad * self.pairs(torque_nm)

    def twist_rad(self, torque_nm):
        """Elastic twist from first contact, rad: theta(T) = integral of dT/K(T) (odd in T).

        Notes
        -----
        With a = Ks·n_max, b = Ks·(n_max − n0), x = |T|/T0:
        theta = (T0/a)·[x + ln(a − b·exp(−x)) − ln(a − b)], whose derivative is
        1/(a − b·exp(−x)) = 1/K(T).
        """
        t = np.asarray(torque_nm, dtype=float)
        a = self.tooth_stiffness_nm_per_rad * self.pairs_max
        b = self.tooth_stiffness_nm_per_rad * (self.pairs_max - self.pairs_at_zero)
        x = np.abs(t) / self.torque_scale_nm
        return np.sign(t) * self.torque_scale_nm / a * (x + np.log(a - b * np.exp(-x)) - np.log(a - b))


@dataclass(frozen=True)
class SyntheticRecord:
    """A synthetic encoder/torque-sensor record and its truth.

    Attributes
    ----------
    frame : pandas.DataFrame
        The record as the rig would write it: ``time_s``, ``input_pulses``,
        ``torque_nm`` (noisy).
    rig : RigConstants
        Rig constants to read it with (including the true Ks and z).
    law : SaturatingStiffness
        The true stiffness law.
    backlash_deg, backlash_centre_deg : float
        True dead-zone width and centre, output degrees.
    max_torque_nm : float
        Turning torque of each cycle, N·m.
    true_angle_deg, true_torque_nm : ndarray
        Noise-free output twist (deg) and torque (N·m) at each sample.
    true_phase : ndarray of str
        ``dead_zone``, ``hold`` (drive at rest, :func:`realistic_encoder_record`) or
        one of the four branch kinds, per sample.
    true_cycle : ndarray of int or None
        Per sample: 0 during the virgin (first) loading and its dwell, then the
        cycle number 1, 2, ... counted by loading branches after it, two per cycle
        (:func:`realistic_encoder_record` only).
    """

    frame: pd.DataFrame
    rig: RigConstants
    law: SaturatingStiffness
    backlash_deg: float
    backlash_centre_deg: float
    max_torque_nm: float
    true_angle_deg: np.ndarray
    true_torque_nm: np.ndarray
    true_phase: np.ndarray
    true_cycle: np.ndarray | None = None


def _cycle_path(law, *, max_torque, backlash_rad, centre_rad, hysteresis_rad, dense):
    """Dense (twist rad, torque N·m, label) path of one cycle, starting at the centre."""
    torque_up = np.linspace(0.0, max_torque, dense)
    bump = hysteresis_rad * np.sin(np.pi * torque_up / max_torque)
    edge = centre_rad + backlash_rad / 2
    twist = law.twist_rad(torque_up)
    zero = np.zeros(dense)
    pieces = [
        (np.linspace(centre_rad, edge, dense), zero, "dead_zone"),
        (edge + twist, torque_up, "positive_loading"),
        ((edge + twist + bump)[::-1], torque_up[::-1], "positive_unloading"),
        (np.linspace(edge, edge - backlash_rad, dense), zero, "dead_zone"),
        (edge - backlash_rad - twist, -torque_up, "negative_loading"),
        ((edge - backlash_rad - twist - bump)[::-1], -torque_up[::-1], "negative_unloading"),
        (np.linspace(edge - backlash_rad, centre_rad, dense), zero, "dead_zone"),
    ]
    return pieces


def _check_parameters(function: str, checks) -> None:
    """Each (name, value, range) through :func:`~vision_torsion.validate.check_number`
    (SceneError naming the function, the parameter, its value and its range)."""
    for name, value, allowed in checks:
        check_number(value, name=f"{function}: {name}", error=SceneError, **allowed)


def synthetic_encoder_record(
    *,
    law: SaturatingStiffness | None = None,
    rig: RigConstants | None = None,
    max_torque_nm: float = 30.0,
    backlash_deg: float = 0.1,
    backlash_centre_deg: float = 0.0,
    hysteresis_deg: float = 0.01,
    torque_noise_nm: float = 0.02,
    cycles: int = 1,
    sampling_rate_hz: float = 100.0,
    drive_speed_deg_per_s: float = 0.01,
    seed: int = 0,
) -> SyntheticRecord:
    """Simulate an encoder/torque-sensor test of a harmonic drive.

    Parameters
    ----------
    law : SaturatingStiffness, optional
        True stiffness law; default :class:`SaturatingStiffness()`.
    rig : RigConstants, optional
        Default: 51200 pulses/rev, ratio 100, sensor 2e4 N·m/rad, z = 160 and
        Ks from `law`.
    max_torque_nm : float
        Turning torque, N·m.
    backlash_deg, backlash_centre_deg : float
        Dead-zone width (> 0) and centre, output degrees.
    hysteresis_deg : float
        Largest loading/unloading twist difference, output degrees (>= 0; small
        enough that unloading stays monotonic).
    torque_noise_nm : float
        Standard deviation of the white torque-sensor noise, N·m.
    cycles : int
        Number of full cycles.
    sampling_rate_hz : float
        Sampling rate, Hz.
    drive_speed_deg_per_s : float
        Drive speed theta_in/i, output degrees per second.
    seed : int
        Seed of ``np.random.default_rng``.

    Returns
    -------
    SyntheticRecord

    Raises
    ------
    SceneError
        A parameter is out of range: the message names it, its value and the range.

    Examples
    --------
    >>> rec = synthetic_encoder_record(seed=1)
    >>> list(rec.frame.columns)
    ['time_s', 'input_pulses', 'torque_nm']
    >>> round(float(rec.frame["torque_nm"].max()))
    30
    """
    law = SaturatingStiffness() if law is None else law
    if rig is None:
        rig = RigConstants(pulses_per_rev=51200, transmission_ratio=100,
                           sensor_stiffness_nm_per_rad=2.0e4, teeth=160,
                           tooth_stiffness_nm_per_rad=law.tooth_stiffness_nm_per_rad)
    if rig.pulses_per_rev is None:
        raise SceneError("the synthetic rig needs pulses_per_rev")
    _check_parameters("synthetic_encoder_record", [
        ("max_torque_nm", max_torque_nm, dict(low=0, low_open=True, unit="N·m")),
        ("backlash_deg", backlash_deg, dict(low=0, low_open=True, unit="degrees")),
        ("backlash_centre_deg", backlash_centre_deg, dict(unit="degrees")),
        ("hysteresis_deg", hysteresis_deg, dict(unit="degrees")),
        ("cycles", cycles, dict(low=1, whole=True)),
        ("torque_noise_nm", torque_noise_nm, dict(low=0, unit="N·m")),
        ("sampling_rate_hz", sampling_rate_hz, dict(low=0, low_open=True, unit="Hz")),
        ("drive_speed_deg_per_s", drive_speed_deg_per_s, dict(low=0, low_open=True, unit="degrees/s")),
    ])
    hysteresis = np.deg2rad(hysteresis_deg)
    min_compliance = 1.0 / law.stiffness(max_torque_nm)
    if not 0 <= hysteresis * np.pi / max_torque_nm < min_compliance:
        raise SceneError(f"hysteresis_deg = {hysteresis_deg} is negative or so large that "
                         "the unloading branch would turn back")

    pieces = _cycle_path(law, max_torque=max_torque_nm, backlash_rad=np.deg2rad(backlash_deg),
                         centre_rad=np.deg2rad(backlash_centre_deg), hysteresis_rad=hysteresis,
                         dense=4000)
    twist = np.concatenate([p[0] for _ in range(cycles) for p in pieces])
    torque = np.concatenate([p[1] for _ in range(cycles) for p in pieces])
    labels = np.concatenate([np.full(len(p[0]), p[2], dtype=object)
                             for _ in range(cycles) for p in pieces])
    sensor = rig.sensor_stiffness_nm_per_rad
    drive = twist + (torque / sensor if sensor is not None else 0.0)  # theta_in / i, rad
    path = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(drive)))])
    step = np.deg2rad(drive_speed_deg_per_s) / sampling_rate_hz
    s = np.arange(0.0, path[-1], step)
    true_torque = np.interp(s, path, torque)
    true_twist = np.interp(s, path, twist)
    true_drive = np.interp(s, path, drive)
    true_phase = labels[np.searchsorted(path, s, side="right") - 1]

    rng = np.random.default_rng(seed)
    pulses = np.round(true_drive * rig.transmission_ratio * rig.pulses_per_rev / (2 * np.pi))
    frame = pd.DataFrame({
        "time_s": np.arange(s.size) / sampling_rate_hz,
        "input_pulses": pulses.astype(np.int64),
        "torque_nm": true_torque + rng.normal(0.0, torque_noise_nm, s.size),
    })
    return SyntheticRecord(
        frame=frame, rig=rig, law=law, backlash_deg=float(backlash_deg),
        backlash_centre_deg=float(backlash_centre_deg), max_torque_nm=float(max_torque_nm),
        true_angle_deg=np.rad2deg(true_twist), true_torque_nm=true_torque, true_phase=true_phase,
    )


def stiffening_law(*, stiffness_at_zero_nm_per_rad: float = 2000.0,
                   stiffness_at_max_nm_per_rad: float = 16000.0, max_torque_nm: float = 30.0,
                   torque_scale_nm: float = 7.5,
                   tooth_stiffness_nm_per_rad: float = 320.0) -> SaturatingStiffness:
    """A :class:`SaturatingStiffness` law going from K(0) to K(max_torque) exactly.

    Parameters
    ----------
    stiffness_at_zero_nm_per_rad, stiffness_at_max_nm_per_rad : float
        K at first contact and at `max_torque_nm`, N·m/rad (0 < first < second).
    max_torque_nm, torque_scale_nm : float
        The torque where K reaches the second value, and T0, N·m.
    tooth_stiffness_nm_per_rad : float
        Ks, N·m/rad per pair (sets n = K/Ks).

    Examples
    --------
    >>> law = stiffening_law()
    >>> round(float(law.stiffness(0.0))), round(float(law.stiffness(30.0)))
    (2000, 16000)
    """
    ks = float(tooth_stiffness_nm_per_rad)
    n0 = stiffness_at_zero_nm_per_rad / ks
    n_top = stiffness_at_max_nm_per_rad / ks
    if not 0 < n0 < n_top:
        raise SceneError("need 0 < stiffness_at_zero_nm_per_rad < stiffness_at_max_nm_per_rad")
    n_max = n0 + (n_top - n0) / -np.expm1(-max_torque_nm / torque_scale_nm)
    return SaturatingStiffness(tooth_stiffness_nm_per_rad=ks, pairs_at_zero=n0, pairs_max=n_max,
                               torque_scale_nm=torque_scale_nm)


def realistic_encoder_record(
    *,
    law: SaturatingStiffness | None = None,
    samples: int = 20000,
    sampling_rate_hz: float = 500.0,
    max_torque_nm: float = 30.0,
    backlash_deg: float = 0.2,
    backlash_centre_deg: float = 0.0,
    friction_ratio: float = 0.05,
    bedding_in_deg: float = 0.02,
    cycles: int = 3,
    dwell_s: float = 1.0,
    torque_noise_nm: float = 0.03,
    hum_nm: float = 0.05,
    hum_hz: float = 50.0,
    seed: int = 0,
) -> SyntheticRecord:
    """An encoder/torque-sensor test as a real rig records it (issue 14's realistic case).

    The drive first loads the gear from the middle of its dead zone (the *virgin*
    loading, which beds the teeth in), dwells, then runs `cycles` full cycles
    (unloading, through the dead zone, negative loading, dwell, negative unloading,
    back through the dead zone, positive loading, dwell) and finally unloads to the
    middle of the dead zone. Samples are spread evenly over the moving part at a
    constant drive speed; each dwell holds the drive still for `dwell_s`.

    The truth is built here from the stiffness law alone (no analysis code):

    - loading branches follow `law` exactly: K(T) = dT/dθ along them is the truth;
    - friction opposes the motion and scales with the load (mesh friction): the
      unloading branch at twist θ carries (1 − μ)/(1 + μ) of the loading torque,
      and at a reversal the torque first drops by that ratio at constant twist
      (stick) before the teeth slide back;
    - the virgin loading starts `bedding_in_deg` further out (first contact
      earlier) and takes up that extra twist linearly in torque, so it is softer
      than the cyclic loadings; after it the dead zone is `backlash_deg` wide;
    - torque noise: white Gaussian (`torque_noise_nm`) plus mains hum
      `hum_nm`·sin(2π·`hum_hz`·t + φ) with a random phase; input pulses quantised.

    Parameters
    ----------
    law : SaturatingStiffness, optional
        Loading-branch stiffness law; default :func:`stiffening_law` (2000 to
        16 000 N·m/rad over 0 to 30 N·m).
    samples : int
        Number of samples (>= 1000).
    sampling_rate_hz : float
        Sampling rate, Hz (above 2·`hum_hz`, so the hum is not aliased).
    max_torque_nm : float
        Turning torque, N·m.
    backlash_deg, backlash_centre_deg : float
        Dead-zone width after bedding-in (> 0) and centre, output degrees.
    friction_ratio : float
        μ in [0, 0.5).
    bedding_in_deg : float
        Extra twist taken up by the virgin loading, output degrees (>= 0, < width).
    cycles : int
        Full cycles after the virgin loading (>= 1).
    dwell_s : float
        Dwell at each reversal, s (>= 0).
    torque_noise_nm, hum_nm, hum_hz : float
        White-noise std (N·m), hum amplitude (N·m) and frequency (Hz).
    seed : int
        Seed of ``np.random.default_rng``.

    Returns
    -------
    SyntheticRecord
        With ``true_cycle`` (0 = virgin loading) and ``hold`` labels in ``true_phase``.

    Raises
    ------
    SceneError
        A parameter is out of range: the message names it, its value and the range.

    Examples
    --------
    >>> rec = realistic_encoder_record(seed=1)
    >>> len(rec.frame), sorted(set(rec.true_cycle.tolist()))
    (20000, [0, 1, 2, 3])
    """
    _check_parameters("realistic_encoder_record", [
        ("samples", samples, dict(low=1000, whole=True)),
        ("hum_hz", hum_hz, dict(low=0, low_open=True, unit="Hz")),
        ("sampling_rate_hz", sampling_rate_hz, dict(low=2 * hum_hz, low_open=True, unit="Hz, above 2·hum_hz")),
        ("max_torque_nm", max_torque_nm, dict(low=0, low_open=True, unit="N·m")),
        ("backlash_deg", backlash_deg, dict(low=0, low_open=True, unit="degrees")),
        ("backlash_centre_deg", backlash_centre_deg, dict(unit="degrees")),
        ("friction_ratio", friction_ratio, dict(low=0, high=0.5, high_open=True)),
        ("bedding_in_deg", bedding_in_deg, dict(low=0, high=backlash_deg, high_open=True,
                                                unit="degrees, below backlash_deg")),
        ("cycles", cycles, dict(low=1, whole=True)),
        ("dwell_s", dwell_s, dict(low=0, unit="s")),
        ("torque_noise_nm", torque_noise_nm, dict(low=0, unit="N·m")),
        ("hum_nm", hum_nm, dict(low=0, unit="N·m")),
    ])
    law = stiffening_law(max_torque_nm=max_torque_nm) if law is None else law
    rig = RigConstants(pulses_per_rev=51200, transmission_ratio=100, sensor_stiffness_nm_per_rad=2.0e4,
                       teeth=160, tooth_stiffness_nm_per_rad=law.tooth_stiffness_nm_per_rad)
    dense = 3000
    ratio = (1.0 - friction_ratio) / (1.0 + friction_ratio)
    centre = np.deg2rad(backlash_centre_deg)
    up, down = centre + np.deg2rad(backlash_deg) / 2, centre - np.deg2rad(backlash_deg) / 2
    t_up = np.linspace(0.0, max_torque_nm, dense)
    twist = law.twist_rad(t_up)
    top = float(twist[-1])
    zero = np.zeros(dense)
    set_rad = np.deg2rad(bedding_in_deg)

    def line(a, b):
        return np.linspace(a, b, dense)

    # (twist rad, torque N·m, label, cycle); "hold" pieces are a single state.
    pieces = [(line(centre, up - set_rad), zero, "dead_zone", 0),
              (up - set_rad + twist + set_rad * t_up / max_torque_nm, t_up, "positive_loading", 0),
              ("hold", max_torque_nm, up + top, 0)]
    for k in range(1, cycles + 1):
        pieces += [
            (np.full(dense, up + top), line(max_torque_nm, ratio * max_torque_nm), "positive_unloading", k),
            ((up + twist)[::-1], (ratio * t_up)[::-1], "positive_unloading", k),
            (line(up, down), zero, "dead_zone", k),
            (down - twist, -t_up, "negative_loading", k),
            ("hold", -max_torque_nm, down - top, k),
            (np.full(dense, down - top), line(-max_torque_nm, -ratio * max_torque_nm), "negative_unloading", k),
            ((down - twist)[::-1], (-ratio * t_up)[::-1], "negative_unloading", k),
            (line(down, up), zero, "dead_zone", k),
            (up + twist, t_up, "positive_loading", k),
            ("hold", max_torque_nm, up + top, k),
        ]
    pieces += [(np.full(dense, up + top), line(max_torque_nm, ratio * max_torque_nm), "positive_unloading", cycles),
               ((up + twist)[::-1], (ratio * t_up)[::-1], "positive_unloading", cycles),
               (line(up, centre), zero, "dead_zone", cycles)]

    sensor = rig.sensor_stiffness_nm_per_rad
    moving = [p for p in pieces if not isinstance(p[0], str)]
    tw = np.concatenate([p[0] for p in moving])
    tq = np.concatenate([p[1] for p in moving])
    lab = np.concatenate([np.full(dense, p[2], dtype=object) for p in moving])
    cyc = np.concatenate([np.full(dense, p[3]) for p in moving])
    drive = tw + tq / sensor
    path = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(drive)))])
    # Path position of each hold: the end of the moving piece before it.
    ends = np.cumsum([dense for _ in moving]) - 1
    hold_at, n_moving_before = [], 0
    for p in pieces:
        if isinstance(p[0], str):
            hold_at.append((path[ends[n_moving_before - 1]], p))
        else:
            n_moving_before += 1
    per_hold = int(round(dwell_s * sampling_rate_hz))
    n_move = samples - per_hold * len(hold_at)
    if n_move < 500:
        raise SceneError("realistic_encoder_record: the dwells leave fewer than 500 moving samples")
    s = np.linspace(0.0, path[-1], n_move)
    idx = np.clip(np.searchsorted(path, s, side="right") - 1, 0, path.size - 1)
    parts = {"twist": [], "torque": [], "drive": [], "label": [], "cycle": []}
    start = 0
    for position, (_, hold_torque, hold_twist, hold_cycle) in hold_at + [(np.inf, (None, None, None, None))]:
        stop = int(np.searchsorted(s, position, side="right"))
        seg = slice(start, stop)
        parts["twist"].append(np.interp(s[seg], path, tw))
        parts["torque"].append(np.interp(s[seg], path, tq))
        parts["drive"].append(np.interp(s[seg], path, drive))
        parts["label"].append(lab[idx[seg]])
        parts["cycle"].append(cyc[idx[seg]])
        if hold_torque is not None:
            parts["twist"].append(np.full(per_hold, hold_twist))
            parts["torque"].append(np.full(per_hold, hold_torque))
            parts["drive"].append(np.full(per_hold, hold_twist + hold_torque / sensor))
            parts["label"].append(np.full(per_hold, "hold", dtype=object))
            parts["cycle"].append(np.full(per_hold, hold_cycle))
        start = stop
    true_twist, true_torque, true_drive = (np.concatenate(parts[k]) for k in ("twist", "torque", "drive"))
    rng = np.random.default_rng(seed)
    time_s = np.arange(samples) / sampling_rate_hz
    noise = rng.normal(0.0, torque_noise_nm, samples) if torque_noise_nm > 0 else 0.0
    hum = hum_nm * np.sin(2 * np.pi * hum_hz * time_s + rng.uniform(0, 2 * np.pi))
    pulses = np.round(true_drive * rig.transmission_ratio * rig.pulses_per_rev / (2 * np.pi))
    frame = pd.DataFrame({"time_s": time_s, "input_pulses": pulses.astype(np.int64),
                          "torque_nm": true_torque + noise + hum})
    return SyntheticRecord(
        frame=frame, rig=rig, law=law, backlash_deg=float(backlash_deg),
        backlash_centre_deg=float(backlash_centre_deg), max_torque_nm=float(max_torque_nm),
        true_angle_deg=np.rad2deg(true_twist), true_torque_nm=true_torque,
        true_phase=np.concatenate(parts["label"]), true_cycle=np.concatenate(parts["cycle"]).astype(int),
    )


def synthetic_measurements(
    *,
    law: SaturatingStiffness | None = None,
    max_torque_nm: float = 30.0,
    steps: int = 10,
    backlash_deg: float = 0.1,
    hysteresis_deg: float = 0.01,
    angle_noise_deg: float = 0.0,
    cycles: int = 1,
    seed: int = 0,
) -> pd.DataFrame:
    """A camera-rig ``measurements.csv`` table of load steps following `law`.

    Each cycle is: a ``reference`` row (zero torque, angle 0), then
    ``positive_unloading`` (T_max to 0), ``negative_loading`` (0 to −T_max),
    ``negative_unloading`` (−T_max to 0) and ``positive_loading`` (0 to T_max), each
    with ``steps + 1`` rows (step 0 at the starting torque). The dead zone is centred
    on angle 0.

    Parameters
    ----------
    law : SaturatingStiffness, optional
        True stiffness law (default :class:`SaturatingStiffness()`).
    max_torque_nm : float
        Largest torque, N·m.
    steps : int
        Load steps per phase.
    backlash_deg, hysteresis_deg : float
        Dead-zone width and hysteresis amplitude, degrees.
    angle_noise_deg : float
        Standard deviation of Gaussian angle noise, degrees.
    cycles : int
        Number of cycles (one orientation, 0°).
    seed : int
        Seed of ``np.random.default_rng``.

    Returns
    -------
    pandas.DataFrame
        Columns :data:`~vision_torsion.stiffness.records.MEASUREMENT_COLUMNS`.

    Examples
    --------
    >>> table = synthetic_measurements(steps=4)
    >>> table["phase"].value_counts()["positive_loading"]
    np.int64(5)
    """
    law = SaturatingStiffness() if law is None else law
    _check_parameters("synthetic_measurements", [("steps", steps, dict(low=1, whole=True)),
                                                 ("cycles", cycles, dict(low=1, whole=True))])
    rng = np.random.default_rng(seed)
    half, hyst = backlash_deg / 2, hysteresis_deg
    frac = np.arange(steps + 1) / steps

    def twist(t):  # output twist of a loaded step, degrees
        return np.sign(t) * half + np.rad2deg(law.twist_rad(t))

    def bump(t):
        return np.sign(t) * hyst * np.sin(np.pi * np.abs(t) / max_torque_nm)

    phases = [
        ("positive_unloading", max_torque_nm * (1 - frac), lambda t: twist(t) + bump(t), half),
        ("negative_loading", -max_torque_nm * frac, twist, half),
        ("negative_unloading", -max_torque_nm * (1 - frac), lambda t: twist(t) + bump(t), -half),
        ("positive_loading", max_torque_nm * frac, twist, -half),
    ]
    rows = []
    for cycle in range(cycles):
        rows.append(("reference", 0, 0.0, 0.0))
        for name, torque, angle_of, rest in phases:
            # A zero-torque step leaves the output where the previous phase let go of it.
            angle = np.where(torque == 0, rest, angle_of(torque))
            rows.extend((name, k, t, a) for k, (t, a) in enumerate(zip(torque, angle)))
    table = pd.DataFrame(rows, columns=["phase", "step", "torque_nm", "angle_deg"])
    n = len(table)
    cycle_index = np.repeat(np.arange(cycles), n // cycles)
    table["angle_deg"] += rng.normal(0.0, angle_noise_deg, n) if angle_noise_deg > 0 else 0.0
    table = table.assign(
        image=[f"img_{k:04d}.png" for k in range(n)], orientation_deg=0.0, cycle=cycle_index,
        mass_kg=np.nan, torque_std_nm=0.0, angle_std_deg=angle_noise_deg, status="ok", message="",
    )
    return table[list(MEASUREMENT_COLUMNS)]
