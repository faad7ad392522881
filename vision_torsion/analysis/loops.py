"""Turn a ``measurements.csv`` table into loops: one validation place for the input.

A *loop* is one cycle at one orientation: positive unloading (+Tmax → 0), negative
loading (0 → −Tmax), negative unloading (−Tmax → 0), positive loading (0 → +Tmax).
Its samples are ordered by phase (in that order) and by ``step`` inside a phase.

For the model-free figures a loop is also seen as two monotone *runs*:
the **descending run** (positive unloading then negative loading, +Tmax → −Tmax) and
the **ascending run** (negative unloading then positive loading, −Tmax → +Tmax).
At equal torque the descending run is the unloading branch on the positive side and
the loading branch on the negative side, so "loading vs unloading at equal torque"
over the whole loop is simply "descending vs ascending". Inside a run, images at the
same nominal torque (the zero at the phase boundary) are merged by averaging.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import AnalysisError
from ..measurements import CYCLE_PHASES, MEASUREMENT_COLUMNS, PHASES, read_measurements
from .uncertainty import compact_sources, torque_sources

__all__ = ["PHASES", "LOOP_PHASES", "REQUIRED_COLUMNS", "validate_measurements", "Loop", "build_loops"]

# The vocabulary is vision_torsion.measurements'; these names are kept for callers.
#: The four phases of one cycle (:data:`vision_torsion.measurements.CYCLE_PHASES`).
LOOP_PHASES = CYCLE_PHASES
#: Columns ``measurements.csv`` must have (:data:`vision_torsion.measurements.MEASUREMENT_COLUMNS`).
REQUIRED_COLUMNS = MEASUREMENT_COLUMNS
#: Optional column: the common (g, r scale) part of ``torque_std_nm``.
OPTIONAL_COLUMNS = ("torque_common_std_nm",)


def validate_measurements(measurements: pd.DataFrame, *, with_closing: bool = False):
    """Check a measurements table and split it into usable rows and failed images.

    Parameters
    ----------
    measurements : pandas.DataFrame
        The table of ``measurements.csv`` (columns :data:`REQUIRED_COLUMNS`).

    Returns
    -------
    usable : pandas.DataFrame
        Rows with ``status == "ok"`` and finite numbers, loop phases only (the
        ``reference`` rows only define the zero angle; ``closing`` rows are not part
        of a loop), sorted by orientation, cycle, phase order, step; a copy (the
        input is not modified).
    failed : pandas.DataFrame
        ``image, orientation_deg, cycle, phase, step, message`` of every image that
        cannot be used, with the reason.
    closing : pandas.DataFrame
        Only with ``with_closing=True``: the usable ``closing`` rows.

    Row numbers in messages are CSV lines (header = line 1, first data row = line 2).

    Raises
    ------
    MeasurementsError (an AnalysisError)
        Not a DataFrame, missing columns, an unknown phase name, a non-numeric value in
        a numeric column, a negative mass or uncertainty (every bad row listed by its
        CSV line, :func:`vision_torsion.measurements.read_measurements`).
    AnalysisError
        No usable row at all.
    """
    if not isinstance(measurements, pd.DataFrame):
        raise AnalysisError(f"measurements must be a pandas DataFrame, got {type(measurements).__name__}")
    raw = read_measurements(measurements, name="measurements table")
    optional = [c for c in OPTIONAL_COLUMNS if c in raw.columns]
    df = raw.loc[:, list(REQUIRED_COLUMNS) + optional]

    reason = pd.Series("", index=df.index)
    not_ok = df["status"] != "ok"
    reason[not_ok] = df.loc[not_ok, "message"].where(
        df.loc[not_ok, "message"] != "", "status " + df.loc[not_ok, "status"]
    )
    for col in ("orientation_deg", "cycle", "step", "torque_nm", "angle_deg", "torque_std_nm", "angle_std_deg"):
        nan = (~not_ok) & (reason == "") & ~np.isfinite(df[col])
        reason[nan] = f"marked ok but {col} is not a finite number"
    failed_mask = reason != ""
    failed = df.loc[failed_mask, ["image", "orientation_deg", "cycle", "phase", "step"]].copy()
    failed["message"] = reason[failed_mask]
    closing = df.loc[~failed_mask & (df["phase"] == "closing")].copy().reset_index(drop=True)
    usable = df.loc[~failed_mask & df["phase"].isin(LOOP_PHASES)].copy()
    if usable.empty:
        raise AnalysisError("measurements table has no usable rows (status == 'ok' with finite torque and angle)")
    usable["_phase_order"] = usable["phase"].map({p: i for i, p in enumerate(PHASES)})
    usable = usable.sort_values(["orientation_deg", "cycle", "_phase_order", "step"], kind="stable")
    usable = usable.drop(columns="_phase_order").reset_index(drop=True)
    if with_closing:
        return usable, failed.reset_index(drop=True), closing
    return usable, failed.reset_index(drop=True)


@dataclass(frozen=True)
class Loop:
    """Samples of one orientation and cycle, in acquisition order.

    Arrays are in N·m and **radians**. ``groups`` indexes the samples of the same
    nominal torque (session-wide), ``torque_sources`` is the loading matrix ``L`` of
    the torque errors of these samples (``δτ = L·ξ``, N·m per unit source; see
    :mod:`.uncertainty`), restricted to the sources that touch this loop.
    """

    orientation_deg: float
    cycle: int
    phase: np.ndarray
    torque_nm: np.ndarray
    torque_std_nm: np.ndarray
    angle_rad: np.ndarray
    angle_std_rad: np.ndarray
    groups: np.ndarray
    images: np.ndarray
    torque_sources: np.ndarray | None = None
    source_kinds: np.ndarray | None = None
    torque_local_std_nm: np.ndarray | None = None

    def local_sources(self) -> np.ndarray:
        """:meth:`sources` without the common g, r scale (it leaves no residual in a fit)."""
        src = self.sources()
        if self.source_kinds is None:
            return src
        return src[:, np.asarray(self.source_kinds) != "g_r"]

    def local_std(self) -> np.ndarray:
        """Image-to-image part of the torque 1σ (N·m; the g, r scale part removed)."""
        return self.torque_std_nm if self.torque_local_std_nm is None else self.torque_local_std_nm

    def sources(self) -> np.ndarray:
        """``torque_sources``, or the ``"level"`` matrix from ``groups`` and ``torque_std_nm``."""
        if self.torque_sources is not None:
            return self.torque_sources
        from .uncertainty import group_sources

        return compact_sources(group_sources(self.groups, self.torque_std_nm))

    def phase_counts(self) -> dict:
        """Number of usable samples in each of the four phases."""
        return {p: int(np.sum(self.phase == p)) for p in LOOP_PHASES}

    def run_matrix(self) -> np.ndarray:
        """``A`` (merged run samples × loop samples): run values = ``A @`` loop values, in :meth:`runs` order."""
        blocks = []
        for phases, descending in ((LOOP_PHASES[:2], True), (LOOP_PHASES[2:], False)):
            m = np.flatnonzero(np.isin(self.phase, phases))
            g = self.groups[m]
            uniq, inv = np.unique(g, return_inverse=True)
            cnt = np.bincount(inv, minlength=uniq.size).astype(float)
            tau = np.bincount(inv, self.torque_nm[m]) / cnt
            avg = np.zeros((uniq.size, self.torque_nm.size))
            avg[inv, m] = 1.0 / cnt[inv]
            order = np.argsort(-tau if descending else tau, kind="stable")
            blocks.append(avg[order])
        return np.vstack(blocks)

    def runs(self):
        """Merged descending and ascending runs: ``(tau, theta, theta_std, tau_std, groups, is_desc, sources)``.

        The descending run comes first, sorted by decreasing torque; the ascending run
        follows, sorted by increasing torque. Samples of the same torque group inside a
        run are averaged (angle std divided by sqrt(count)); ``sources`` (merged
        samples × torque sources) is the same average of the rows of
        :meth:`sources`, so merged samples keep their torque correlations.
        """
        src = self.sources()
        out = []
        for phases, descending in ((LOOP_PHASES[:2], True), (LOOP_PHASES[2:], False)):
            m = np.isin(self.phase, phases)
            g = self.groups[m]
            uniq, inv = np.unique(g, return_inverse=True)
            cnt = np.bincount(inv, minlength=uniq.size).astype(float)
            tau = np.bincount(inv, self.torque_nm[m]) / cnt
            th = np.bincount(inv, self.angle_rad[m]) / cnt
            var = np.bincount(inv, self.angle_std_rad[m] ** 2) / cnt**2
            tstd = np.zeros(uniq.size)
            np.maximum.at(tstd, inv, self.torque_std_nm[m])
            avg = np.zeros((uniq.size, int(m.sum())))
            avg[inv, np.arange(inv.size)] = 1.0 / cnt[inv]
            srcs = avg @ src[m]
            order = np.argsort(-tau if descending else tau, kind="stable")
            out.append(
                (
                    tau[order],
                    th[order],
                    np.sqrt(var[order]),
                    tstd[order],
                    uniq[order],
                    np.full(order.size, descending),
                    srcs[order],
                )
            )
        return tuple(np.concatenate(parts) for parts in zip(*out))


def build_loops(usable: pd.DataFrame, *, torque_correlation="level", rig=None) -> list[Loop]:
    """Group usable rows into :class:`Loop` objects, one per (orientation, cycle).

    Torque groups and sources are formed over the whole session, so a level (or a
    weight piece) shares its error across orientations and cycles (see
    :mod:`.uncertainty`, :func:`.uncertainty.torque_sources`).
    """
    from .fitcheck import local_torque_std

    sources, groups, kinds = torque_sources(usable, correlation=torque_correlation, rig=rig, return_kinds=True)
    common = usable["torque_common_std_nm"].to_numpy(float) if "torque_common_std_nm" in usable else None
    local = local_torque_std(usable["torque_std_nm"].to_numpy(float), common)
    loops = []
    tau_all = usable["torque_nm"].to_numpy(float)
    orient_all = usable["orientation_deg"].to_numpy(float)
    phase_all = usable["phase"].to_numpy(object)
    for (orient, cycle), idx in usable.groupby(["orientation_deg", "cycle"], sort=True).indices.items():
        idx = np.asarray(idx)
        # a later cycle starts where the one before ended (+Tmax, the last positive_loading image, which the
        # protocol does not photograph twice): that image is also this loop's start
        top = tau_all[orient_all == orient].max()
        i0 = idx[0]
        if (abs(tau_all[i0] - top) > 1e-9 and i0 > 0 and orient_all[i0 - 1] == orient
                and phase_all[i0 - 1] == "positive_loading" and abs(tau_all[i0 - 1] - top) <= 1e-9
                and phase_all[i0] == "positive_unloading"):
            idx = np.concatenate([[i0 - 1], idx])
        sub = usable.iloc[idx]
        phase = sub["phase"].to_numpy(dtype=object).copy()
        if phase[0] == "positive_loading":
            phase[0] = "positive_unloading"  # the borrowed start image begins this loop's unloading
        loops.append(Loop(
            orientation_deg=float(orient), cycle=int(cycle),
            phase=phase,
            torque_nm=sub["torque_nm"].to_numpy(float),
            torque_std_nm=sub["torque_std_nm"].to_numpy(float),
            angle_rad=np.radians(sub["angle_deg"].to_numpy(float)),
            angle_std_rad=np.radians(sub["angle_std_deg"].to_numpy(float)),
            groups=groups[idx],
            images=sub["image"].astype(str).to_numpy(dtype=object),
            torque_sources=compact_sources(sources[idx], kinds)[0],
            source_kinds=compact_sources(sources[idx], kinds)[1],
            torque_local_std_nm=local[idx],
        ))
    return loops
