"""``analyze_table``: any torque–angle table in, summary.json and report.html out.

The one path from a table to a report: ``vision-torsion analyze TABLE.csv`` and
``vision-torsion report SESSION_DIR`` (after processing) both come here.

The table is a ``measurements.csv`` or one from another rig with the same columns
(docs/analysis.md lists them: ``image, orientation_deg, cycle, phase, step, mass_kg,
torque_nm, torque_std_nm, angle_deg, angle_std_deg, status, message``, optional
``torque_common_std_nm``). A ``session.toml`` is optional: with it the torque
uncertainty follows the weight pieces (its ``[rig]``), lost motion refers to the
rated torque and K1–K3 to the catalogue breaks (its ``[gear]``), and the test's
metadata (its ``[test]``) are shown in the report and written into summary.json.

The torque-error model must be declared: a ``session.toml`` (its ``[rig]``), or the
rig's constants as explicit options (``rig_options``: piece tolerance, pieces per
step, g, r; :func:`rig_from_options`). Without either, every figure is flagged
"torque uncertainty not modelled" (:data:`vision_torsion.analysis.session_analysis.TORQUE_NOT_MODELLED`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import AnalysisError

__all__ = ["AnalyzeResult", "analyze_table", "analysis_options", "test_metadata", "withheld_by_kind",
           "describe_withheld", "angle_sign_advice", "spec_limits", "identity", "gear_options",
           "merge_catalogue", "rig_from_options", "RIG_OPTIONS"]

#: Keys of ``rig_options`` (:func:`rig_from_options`), all required together.
RIG_OPTIONS = ("piece_tolerance_kg", "pieces_per_step", "gravity_m_per_s2", "arm_radius_m")

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class AnalyzeResult:
    """What :func:`analyze_table` wrote and found.

    Attributes
    ----------
    files : vision_torsion.report.ReportFiles
    analysis : vision_torsion.analysis.SessionAnalysis
    n_rows, n_failed : int
        Rows of the table and images that could not be used.
    n_issues, n_withheld, n_flagged : int
        Issues listed, figures withheld (null with a reason) and flagged.
    withheld_by_kind : dict
        Withheld figures by :data:`~vision_torsion.analysis.session_analysis.ISSUE_KINDS`
        (``rejected``, ``not_applicable``, ``not_computable``); see :func:`withheld_by_kind`.
    angle_sign_advice : str
        What to set when the angle falls as the torque rises (:func:`angle_sign_advice`),
        empty otherwise.
    import_notes : tuple of str
        What reading a table from elsewhere did (:attr:`~vision_torsion.table_import.ImportedTable.notes`).
    verdicts : tuple of Verdict or None
        The conformity verdicts against the ``[spec]`` limits (None without any).
    """

    files: object
    analysis: object
    n_rows: int
    n_failed: int
    n_issues: int
    n_withheld: int
    n_flagged: int
    withheld_by_kind: dict = field(default_factory=dict)
    angle_sign_advice: str = ""
    import_notes: tuple = ()
    verdicts: tuple | None = None


def angle_sign_advice(angle_sign: int = 1) -> str:
    """What to do when the angle falls as the torque rises: set the opposite of the
    session's ``angle_sign`` (+1 unless session.toml says otherwise).

    Examples
    --------
    >>> angle_sign_advice()
    'angle_sign looks inverted; set angle_sign = -1 in session.toml and process the images again'
    """
    if angle_sign < 0:
        return ("angle_sign looks inverted; set angle_sign = 1 in session.toml (it is -1 now) and process the "
                "images again, or negate the table's angle_deg")
    return "angle_sign looks inverted; set angle_sign = -1 in session.toml and process the images again"


def withheld_by_kind(analysis) -> dict:
    """How many figures are withheld, by what a reader is told: ``{"rejected": n,
    "not_applicable": n, "not_computable": n}``.

    A withheld figure is a figure row with no value; its kind is its issue's
    (:class:`~vision_torsion.analysis.Issue`), "not_computable" when it has none.
    """
    kinds = {(i.orientation_deg, i.cycle, i.figure): i.kind for i in analysis.issues if i.kind != "flagged"}
    out = {"rejected": 0, "not_applicable": 0, "not_computable": 0}
    f = analysis.figures
    for o, c, name, v in zip(f["orientation_deg"], f["cycle"], f["figure"], f["value"]):
        if v == v:  # a value: not withheld
            continue
        kind = kinds.get((o, c, name), "not_computable")
        out[kind] = out.get(kind, 0) + 1
    return out


def describe_withheld(counts: dict, n_flagged: int | None = None) -> str:
    """One line for the command line: the withheld figures by kind, and the flagged ones.

    Examples
    --------
    >>> line = describe_withheld({"rejected": 12, "not_applicable": 12, "not_computable": 0}, 0)
    >>> line.split(": ")[0], line.split("; ")[1]
    ('24 figure(s) withheld', '0 flagged')
    """
    n = sum(counts.values())
    text = (f"{n} figure(s) withheld: {counts.get('rejected', 0)} do not fit their data (given another way), "
            f"{counts.get('not_applicable', 0)} not applicable to these data, "
            f"{counts.get('not_computable', 0)} not computable")
    if n_flagged is not None:
        text += f"; {n_flagged} flagged"
    return text + "; each with its reason in the report"


def rig_from_options(table: pd.DataFrame, *, piece_tolerance_kg, pieces_per_step, gravity_m_per_s2, arm_radius_m):
    """The weight-piece rig of a table analysed without its session.toml, from explicit options.

    Parameters
    ----------
    table : pandas.DataFrame
        The table (its ``mass_kg`` column: the mass on each pan, kg).
    piece_tolerance_kg : float
        Tolerance of one weight piece, ±kg (a uniform distribution: 1σ = tolerance/√3).
    pieces_per_step : int
        Pieces added to each pan per step; one piece's mass is the table's mass step
        (the smallest difference between its distinct positive ``mass_kg`` values, and
        the smallest of them) divided by this.
    gravity_m_per_s2, arm_radius_m : float
        Local g (m/s²) and the arm radius r (m).

    Returns
    -------
    vision_torsion.measurements.TorqueRig

    Raises
    ------
    AnalysisError
        A value out of range (named), or a table without a positive ``mass_kg``.
    """
    from ..measurements import TorqueRig

    for name, v, lo in (("piece_tolerance_kg", piece_tolerance_kg, 0.0), ("gravity_m_per_s2", gravity_m_per_s2, None),
                        ("arm_radius_m", arm_radius_m, None)):
        ok = isinstance(v, (int, float)) and math.isfinite(v) and (v >= lo if lo is not None else v > 0)
        if not ok:
            raise AnalysisError(f"rig option {name} must be a {'non-negative' if lo is not None else 'positive'} "
                                f"number, got {v!r}", reason="bad_rig")
    if not (isinstance(pieces_per_step, int) and pieces_per_step >= 1):
        raise AnalysisError(f"rig option pieces_per_step must be a whole number >= 1, got {pieces_per_step!r}",
                            reason="bad_rig")
    mass = pd.to_numeric(table["mass_kg"], errors="coerce").to_numpy(float) if "mass_kg" in table else np.zeros(0)
    levels = np.unique(np.round(mass[np.isfinite(mass) & (mass > 0)], 9))
    if levels.size == 0:
        raise AnalysisError("the rig options need the table's mass_kg (the mass on each pan, kg); it has no "
                            "positive value", reason="bad_rig")
    step = float(min(levels[0], np.min(np.diff(levels)))) if levels.size > 1 else float(levels[0])
    return TorqueRig(step_mass_kg=step / pieces_per_step, mass_std_kg=piece_tolerance_kg / math.sqrt(3.0),
                     gravity_m_per_s2=float(gravity_m_per_s2), arm_radius_m=float(arm_radius_m))


def analysis_options(config) -> dict:
    """Keyword arguments of :func:`~vision_torsion.analysis.analyze_session` from a session.toml.

    ``[rig]`` and ``[protocol]`` give the weight-piece torque model and the maximum
    torque; ``[gear]`` the rated torque, catalogue T1/T2 and gear ratio; ``[test]`` the
    lost-motion fractions, the secant interval and whether to fit the breaks.
    """
    proto, test = config.protocol, config.test
    kw = dict(
        max_torque_nm=proto.max_torque_nm,
        rig=config.rig,
        fit_breaks=test.fit_breaks,
        **gear_options(config.gear),
    )
    if test.lost_motion_fractions is not None:
        kw["lost_motion_fractions"] = tuple(test.lost_motion_fractions)
    if test.secant_interval_nm is not None:
        kw["secant_interval_nm"] = tuple(test.secant_interval_nm)
    return kw


def gear_options(gear) -> dict:
    """Keyword arguments of :func:`~vision_torsion.analysis.analyze_session` from a
    ``[gear]`` table: the rated torque, the gear ratio and the catalogue T1/T2."""
    kw = dict(rated_torque_nm=gear.rated_torque_nm, gear_ratio=gear.ratio)
    if gear.t1_nm is not None and gear.t2_nm is not None:
        kw["catalogue_breaks_nm"] = (gear.t1_nm, gear.t2_nm)
    return kw


def merge_catalogue(config, catalogue):
    """`config` (a SessionConfig, or None for a table without one) with a catalogue
    file's ``[gear]`` and ``[spec]`` filling what it does not give.

    Returns
    -------
    (gear, test, spec)
        GearConfig, TestConfig, SpecConfig to analyse and report with.

    Raises
    ------
    SessionError
        The catalogue file is invalid, or it and session.toml give one key different
        values (both named).
    """
    import dataclasses

    from ..errors import SessionError
    from ..session.config import GearConfig, SpecConfig, TestConfig, load_catalogue

    gear, test, spec = ((config.gear, config.test, config.spec) if config is not None
                        else (GearConfig(), TestConfig(), SpecConfig()))
    if catalogue is None:
        return gear, test, spec
    cat_gear, cat_spec = load_catalogue(catalogue)
    merged = []
    for table, mine, theirs in (("gear", gear, cat_gear), ("spec", spec, cat_spec)):
        changes = {}
        for f in dataclasses.fields(mine):
            a, b = getattr(mine, f.name), getattr(theirs, f.name)
            if b is None:
                continue
            if a is not None and a != b:
                raise SessionError(f"{table}.{f.name}: session.toml gives {a!r}, the catalogue file {catalogue} "
                                   f"gives {b!r}; keep one", reason="conflict")
            changes[f.name] = b
        merged.append(dataclasses.replace(mine, **changes))
    return merged[0], test, merged[1]


def test_metadata(config=None, *, gear=None, test=None) -> dict:
    """The ``[gear]`` and ``[test]`` entries that were given, for the report and
    summary.json: of `config`, or of the `gear` and `test` tables given."""
    if config is not None:
        gear, test = config.gear, config.test
    out = {}
    for table, obj in (("gear", gear), ("test", test)):
        if obj is None:
            continue
        d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(obj).items() if v is not None}
        if table == "test" and d.get("fit_breaks") is True:
            d.pop("fit_breaks")
        if d:
            out[table] = d
    return out


_LABELS = {
    ("gear", "name"): "gear",
    ("gear", "serial"): "serial number",
    ("gear", "ratio"): "gear ratio i",
    ("gear", "rated_torque_nm"): "rated torque T_R (N·m)",
    ("gear", "t1_nm"): "catalogue T1 (N·m)",
    ("gear", "t2_nm"): "catalogue T2 (N·m)",
    ("test", "operator"): "operator",
    ("test", "date"): "test date",
    ("test", "temperature_c"): "temperature (°C)",
    ("test", "notes"): "notes",
    ("test", "lost_motion_fractions"): "lost motion at (fractions of T_R)",
    ("test", "secant_interval_nm"): "secant interval (N·m)",
    ("test", "fit_breaks"): "fit break torques",
}


def spec_limits(spec, figures=()) -> list:
    """The :class:`~vision_torsion.analysis.conformity.Limit` list of a ``[spec]``
    table (:class:`~vision_torsion.session.config.SpecConfig`), in the analysis'
    units (N·m/rad, degrees).

    The lost-motion maximum applies to every lost-motion figure among `figures`
    (the analysis' figure names: one per ``[test] lost_motion_fractions``, ±3 % and
    ±4 % of T_R by default).
    """
    from ..analysis.conformity import Limit

    out = [Limit(f"k{i}", "min", v) for i, v in
           enumerate((spec.k1_min_nm_per_rad, spec.k2_min_nm_per_rad, spec.k3_min_nm_per_rad), start=1)
           if v is not None]
    if spec.lost_motion_max_arcmin is not None:
        out += [Limit(f, "max", spec.lost_motion_max_arcmin / 60.0) for f in figures if f.startswith("lost_motion_")]
    if spec.hysteresis_loss_max_arcmin is not None:
        out.append(Limit("hysteresis_loss", "max", spec.hysteresis_loss_max_arcmin / 60.0))
    return out


def identity(gear, test) -> dict:
    """Who, what, when: ``{"gear", "serial", "operator", "date", "notes"}`` from the
    ``[gear]`` and ``[test]`` tables (Gear-/TestConfig), the entries given only."""
    out = {"gear": gear.name, "serial": gear.serial, "operator": test.operator, "date": test.date,
           "notes": test.notes}
    return {k: v for k, v in out.items() if v}


_IDENTITY_KEYS = {("gear", "name"), ("gear", "serial"), ("test", "operator"), ("test", "date"), ("test", "notes")}


def _read_table(table, **import_options) -> tuple[pd.DataFrame, str, tuple]:
    if isinstance(table, pd.DataFrame):
        return table, "table", ()
    from ..table_import import import_table

    # the one reader of a table file: a measurements.csv as it is, any other through the import
    imported = import_table(table, name=str(table), **import_options)
    return imported.frame, str(table), imported.notes


def analyze_table(
    table,
    *,
    session=None,
    out_dir=None,
    conditions=None,
    extra_sections=(),
    failures=None,
    title="Torsional stiffness and hysteresis report",
    n_draws=400,
    seed=0,
    columns=None,
    units=None,
    angle_std_deg=None,
    torque_std_nm=None,
    catalogue=None,
    rig_options=None,
):
    """Analyse a torque–angle table and write summary.json, stiffness_table.csv, figures and report.html.

    Parameters
    ----------
    table : path-like or pandas.DataFrame
        ``measurements.csv`` or a table with the same columns (rows with status
        ``pending`` are skipped: not photographed yet).
    session : path-like or SessionConfig, optional
        A ``session.toml`` (or its parsed :class:`~vision_torsion.session.SessionConfig`)
        for the rig, the protocol and the optional ``[gear]``/``[test]`` tables.
    out_dir : path-like, optional
        Output folder; default ``<table folder>/<table stem>_analysis``.
    conditions : dict, optional
        Test conditions to show first (default: the table, and the session's rig).
    extra_sections : sequence of (title, html)
        Further report sections.
    failures : list of dict, optional
        Further failed images (see :func:`~vision_torsion.report.write_report`).
    title : str
    n_draws, seed : int
        Monte Carlo settings of the analysis.
    columns, units : dict, optional
        For a table from elsewhere: quantity -> header, and quantity -> unit
        (:func:`vision_torsion.table_import.import_table`; separators, decimal
        commas, units in headers and a plain torque/angle record are handled there).
    angle_std_deg, torque_std_nm : float, optional
        1σ of every angle and torque, for a table without uncertainty columns.
    catalogue : path-like, optional
        A catalogue file (``[gear]`` and ``[spec]``,
        :func:`~vision_torsion.session.config.load_catalogue`): with or without a
        session, the catalogue values and the conformity verdict.
    rig_options : dict, optional
        Without ``session``: the rig's constants (:data:`RIG_OPTIONS`, see
        :func:`rig_from_options`). Without either, every figure is flagged "torque
        uncertainty not modelled".

    Returns
    -------
    AnalyzeResult

    Raises
    ------
    AnalysisError
        The table is missing, unreadable, or lacks a column (named), or has no usable
        row; the message starts with the file name.
    SessionError
        The session.toml or the catalogue file is invalid (every problem listed),
        or the two give one key different values.
    """
    from ..analysis import analyze_session
    from ..fileio import output_set
    from . import write_report

    df, name, import_notes = _read_table(table, column_map=columns, units=units, angle_std_deg=angle_std_deg,
                                         torque_std_nm=torque_std_nm)
    if "status" in df.columns:
        df = df[df["status"].astype(str) != "pending"].reset_index(drop=True)
    config = None
    if session is not None:
        if hasattr(session, "protocol"):
            config = session
        else:
            from ..session.config import load_config

            config = load_config(session)
    gear, test, spec = merge_catalogue(config, catalogue)
    if config is not None:
        import dataclasses

        config = dataclasses.replace(config, gear=gear, spec=spec)
    kw = analysis_options(config) if config is not None else gear_options(gear)
    if rig_options is not None:
        if config is not None:
            raise AnalysisError(f"{name}: give the rig either by its session.toml or by the rig options, not both",
                                reason="bad_rig")
        missing = [k for k in RIG_OPTIONS if rig_options.get(k) is None]
        if missing:
            raise AnalysisError(f"{name}: the rig options go together; missing {', '.join(missing)}",
                                reason="bad_rig")
        kw["rig"] = rig_from_options(df, **{k: rig_options[k] for k in RIG_OPTIONS})
    elif config is None:
        kw["torque_model_declared"] = False
    try:
        analysis = analyze_session(df, n_draws=n_draws, seed=seed, **kw)
    except AnalysisError as exc:
        if str(exc).startswith(name):
            raise
        raise type(exc)(f"{name}: {exc}", reason=getattr(exc, "reason", None)) from None
    verdicts = None
    if spec:
        from ..analysis.conformity import conformity

        verdicts = conformity(analysis.summary, spec_limits(spec, analysis.summary))
    meta = test_metadata(gear=gear, test=test)
    analysis.settings["test_metadata"] = meta
    cond = dict(conditions) if conditions is not None else {"table": name}
    if import_notes:
        cond["table import"] = "; ".join(import_notes)
    if conditions is None and config is not None:
        cond.update(
            {
                "arm radius r (m)": config.rig.arm_radius_m,
                "gravity g (m/s²)": config.rig.gravity_m_per_s2,
                "mass per weight piece (kg)": config.rig.step_mass_kg,
                "maximum torque (N·m)": config.protocol.max_torque_nm,
            }
        )
    # the header of the report shows the test's metadata (gear, serial, operator, ...)
    # (who, what and when lead page 1 and summary.json's "identity": not repeated here)
    metadata = {_LABELS.get((t, k), f"{t}.{k}"): v for t, entries in meta.items() for k, v in entries.items()
                if (t, k) not in _IDENTITY_KEYS}
    if out_dir is None:
        if isinstance(table, pd.DataFrame):
            raise AnalysisError("out_dir is needed when the table is a DataFrame")
        out_dir = Path(table).parent / f"{Path(table).stem}_analysis"
    from .analysis_sections import analysis_sections

    sections = [*analysis_sections(analysis), *extra_sections]
    with output_set():  # the report's files are replaced together or not at all
        files = write_report(
            df,
            analysis,
            conditions=cond,
            out_dir=out_dir,
            failures=failures,
            extra_sections=sections,
            title=title,
            metadata=metadata,
            identity=identity(gear, test),
            verdicts=verdicts,
        )
    f = analysis.figures
    by_kind = withheld_by_kind(analysis)
    flagged = int((f["flag"].astype(str) != "").sum())
    return AnalyzeResult(
        files=files,
        analysis=analysis,
        n_rows=int(len(df)),
        n_failed=int(len(analysis.failed_images)),
        n_issues=len(analysis.issues),
        n_withheld=sum(by_kind.values()),
        n_flagged=flagged,
        withheld_by_kind=by_kind,
        angle_sign_advice=angle_sign_advice(config.angle_sign if config is not None else 1)
        if analysis.checks.get("angle_sign_inverted") else "",
        import_notes=tuple(import_notes),
        verdicts=None if verdicts is None else tuple(verdicts),
    )
