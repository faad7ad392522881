"""Zero-phase Butterworth low-pass filtering of torque-angle records.

The stiffness paper removes high-frequency interference from the torque and angle
signals with a Butterworth low-pass filter. Running the filter forwards and backwards
(``scipy.signal.sosfiltfilt``) cancels its phase lag, so the filtered torque is not
shifted against the angle (a lag would open a false hysteresis loop). Second-order
sections (``butter(..., output="sos")``) keep high orders numerically stable.

The filter assumes uniform sampling; the sampling rate is taken as the inverse of
the median time step.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import signal

from ..errors import AnalysisError, RecordError
from .records import TorqueAngleRecord

__all__ = ["lowpass", "default_cutoff_hz", "sampling_rate_hz", "filter_record"]

log = logging.getLogger(__name__)

#: The default cut-off as a fraction of the sampling rate (a tenth of Nyquist):
#: quasi-static loading changes over seconds, so 5 Hz at 100 Hz sampling keeps the
#: curve and removes most white sensor noise (its std falls to about a third).
DEFAULT_CUTOFF_FRACTION = 0.05
#: ... but never above this, Hz: mains hum (50/60 Hz) must lie well in the stop band.
#: At 1 kHz sampling a 5 % cut-off would sit on 50 Hz hum, which then flickers the
#: torque in and out of the zero band near zero torque; 20 Hz damps it ~1500-fold.
MAX_DEFAULT_CUTOFF_HZ = 20.0


def sampling_rate_hz(time_s) -> float:
    """Sampling rate, Hz, as 1 / median time step.

    Parameters
    ----------
    time_s : array_like
        Strictly increasing sample times, s.

    Returns
    -------
    float

    Examples
    --------
    >>> sampling_rate_hz([0.0, 0.01, 0.02, 0.03])
    100.0
    """
    t = np.asarray(time_s, dtype=float)
    dt = np.diff(t)
    rate = 1.0 / float(np.median(dt))
    spread = (dt.max() - dt.min()) / np.median(dt)
    if spread > 0.05:
        log.warning("time steps vary by %.0f %% of the median step; the low-pass filter "
                    "assumes uniform sampling", 100 * spread)
    return round(rate, 9)


def default_cutoff_hz(sampling_rate: float) -> float:
    """Default cut-off frequency, Hz: :data:`DEFAULT_CUTOFF_FRACTION` of the sampling
    rate, at most :data:`MAX_DEFAULT_CUTOFF_HZ` (below mains hum).

    Examples
    --------
    >>> default_cutoff_hz(100.0), default_cutoff_hz(1000.0)
    (5.0, 20.0)
    """
    return min(DEFAULT_CUTOFF_FRACTION * float(sampling_rate), MAX_DEFAULT_CUTOFF_HZ)


def lowpass(values, *, sampling_rate: float, cutoff_hz: float | None = None, order: int = 4):
    """Zero-phase Butterworth low-pass filter of a uniformly sampled signal.

    Parameters
    ----------
    values : array_like
        The signal (any unit); not modified.
    sampling_rate : float
        Sampling rate, Hz.
    cutoff_hz : float, optional
        -3 dB cut-off frequency, Hz (of each pass; the forward-backward filter has
        -6 dB there). Default :func:`default_cutoff_hz`.
    order : int
        Butterworth order of each pass (the forward-backward filter has twice the
        attenuation slope).

    Returns
    -------
    ndarray
        The filtered signal, same length, no phase shift.

    Raises
    ------
    AnalysisError
        `cutoff_hz` is not above 0 or not below the Nyquist frequency, or `order` < 1.
    RecordError
        The signal is too short for the forward-backward filter's edge padding.

    Examples
    --------
    >>> t = np.arange(1000) / 100.0
    >>> slow, fast = np.sin(2 * np.pi * 0.2 * t), 0.5 * np.sin(2 * np.pi * 30 * t)
    >>> y = lowpass(slow + fast, sampling_rate=100.0, cutoff_hz=5.0)
    >>> bool(np.max(np.abs(y - slow)[100:-100]) < 1e-3)
    True
    """
    nyquist = 0.5 * float(sampling_rate)
    cutoff = default_cutoff_hz(sampling_rate) if cutoff_hz is None else float(cutoff_hz)
    if not 0 < cutoff < nyquist:
        raise AnalysisError(
            f"cutoff_hz = {cutoff:g} Hz must be above 0 and below the Nyquist frequency "
            f"{nyquist:g} Hz (half the sampling rate {float(sampling_rate):g} Hz)"
        )
    if int(order) != order or order < 1:
        raise AnalysisError(f"filter order must be a whole number >= 1, got {order!r}")
    sos = signal.butter(int(order), cutoff, btype="lowpass", fs=float(sampling_rate), output="sos")
    x = np.asarray(values, dtype=float)
    # sosfiltfilt pads each end by this many samples (its documented default).
    padlen = 3 * (2 * len(sos) + 1 - min((sos[:, 2] == 0).sum(), (sos[:, 5] == 0).sum()))
    if x.size <= padlen:
        raise RecordError(
            f"too few points to filter: {x.size} samples, a Butterworth filter of order "
            f"{order} needs more than {padlen}"
        )
    return signal.sosfiltfilt(sos, x)


def filter_record(record: TorqueAngleRecord, *, cutoff_hz: float | None = None,
                  order: int = 4) -> TorqueAngleRecord:
    """Low-pass the torque, angle and drive signals of a timed record.

    Parameters
    ----------
    record : TorqueAngleRecord
        Needs ``time_s``; a camera-rig record (load steps, no time) is returned
        unchanged, since a step series is not a sampled signal.
    cutoff_hz : float, optional
        Cut-off, Hz; default from the sampling rate (:func:`default_cutoff_hz`).
    order : int
        Butterworth order.

    Returns
    -------
    TorqueAngleRecord
        A new record with filtered signals.

    Raises
    ------
    AnalysisError, RecordError
        As :func:`lowpass`.
    """
    if record.time_s is None:
        return record
    rate = sampling_rate_hz(record.time_s)
    changes = {
        attr: lowpass(getattr(record, attr), sampling_rate=rate, cutoff_hz=cutoff_hz, order=order)
        for attr in ("angle_deg", "torque_nm", "drive_deg")
        if getattr(record, attr) is not None
    }
    return record.replace(**changes)
