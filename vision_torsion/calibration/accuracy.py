"""Accuracy check against a reference: ``check_accuracy`` (``vision-torsion check-accuracy``).

A check folder holds images and ``reference.csv`` (``image,reference_angle_deg``;
the first row is the reference image; angles in degrees, counter-clockwise positive
as displayed). Every other row's image is measured against the first row's image,
and its measured angle is ``reference_angle_deg[0] + rotation``. Marker identity
(which of two equal markers is which) is settled by the reference angles
themselves: the rotation is the candidate nearest ``reference_angle_deg -
reference_angle_deg[0]`` (:func:`vision_torsion.angle.sequence_angles` with
predictions), so rows may come in any order and rotations may be large; an error
of 90° or more would be read as a swap (the check's tolerance is far smaller). One bad
image gets status ``failed`` and the run goes on.

Outputs (written atomically and as a set to the output folder, ``DIR/results`` by
default; nothing else in DIR is touched, and ``DIR`` itself is refused as the output
folder, since a result written among the images would be taken for an image):

- ``accuracy.csv``: ``image,reference_angle_deg,measured_angle_deg,error_deg,
  angle_std_deg,status`` (status ``reference``, ``ok`` or ``failed: reason``);
- ``accuracy.json``: the summary of :class:`AccuracyResult` (see there);
- ``accuracy.png``: error against reference angle with the ±tolerance band and
  1σ error bars.

Figures (over the ``ok`` rows, the reference row excluded):
error e = measured - reference; bias = mean(e); RMS = sqrt(mean(e²)) (bias
included); largest absolute error; a least-squares line measured = (1 + s)·reference
+ b gives the scale error s and offset b, and the residual RMS after it. The
expanded uncertainty is U95 = k·u with u = sqrt(RMS² + u_ref²) (the observed error
spread about zero, bias included, and the reference's own standard uncertainty from
the spec) and k = t₀.₉₇₅ with n - 1 degrees of freedom (Student; 2.09 for n = 20).
The check passes when every image was measured and every |e| ≤ tolerance.

Spec files (TOML, e.g. ``calibration/rotary_stage.toml``)::

    description = "free text"
    tolerance_deg = 0.02            # pass band ±tolerance (deg)
    reference_std_deg = 0.0         # standard uncertainty of the reference angles (deg)
    correction = "plane.toml"       # optional, relative to the spec file
    [markers]                       # optional MeasureSettings fields
    polarity = "dark"
    fit = "pixels"
    radius_range = [20.0, 60.0]

Arguments given to :func:`check_accuracy` take precedence over the spec.
"""

from __future__ import annotations

import csv
import io
import logging
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from ..correction import load_correction
from ..errors import OutputError, ReferenceTableError, VisionTorsionError
from ..fileio import check_output_dir, output_set, same_folder, write_csv, write_json
from ..measure import measure_sequence
from ..measurements import output_folder
from ..pair import measure_pair
from ..settings import MeasureSettings
from ..textfiles import csv_delimiter, decode_utf8, read_text_bytes, read_toml
from ..validate import check_number

__all__ = [
    "AccuracyResult",
    "AccuracySpec",
    "check_accuracy",
    "load_spec",
    "read_reference_table",
    "ACCURACY_COLUMNS",
    "DEFAULT_TOLERANCE_DEG",
]

logger = logging.getLogger(__name__)

#: The paper's stated uncertainty of the rotary-stage check (deg).
DEFAULT_TOLERANCE_DEG = 0.02
ACCURACY_COLUMNS = ["image", "reference_angle_deg", "measured_angle_deg", "error_deg", "angle_std_deg", "status"]


@dataclass(frozen=True)
class AccuracySpec:
    """A ready check: tolerance, reference uncertainty, marker settings, correction."""

    tolerance_deg: float = DEFAULT_TOLERANCE_DEG
    reference_std_deg: float = 0.0
    settings: MeasureSettings | None = None
    correction: str | None = None
    description: str = ""


@dataclass(frozen=True)
class AccuracyResult:
    """Outcome of :func:`check_accuracy`.

    Attributes
    ----------
    table : pandas.DataFrame
        :data:`ACCURACY_COLUMNS`, one row per reference.csv row.
    n, n_failed : int
        Images measured (reference excluded) and images that failed.
    bias_deg, rms_deg, max_abs_error_deg : float
        Mean error, RMS error (bias included) and largest |error| (deg).
    scale_error, offset_deg, fit_residual_rms_deg : float
        Line measured = (1 + scale_error)·reference + offset_deg, and the RMS of the
        residuals about it (deg).
    u95_deg, coverage_factor : float
        Expanded uncertainty U95 = k·sqrt(RMS² + reference_std²) (deg) and its k.
    tolerance_deg : float
        Pass band ±tolerance (deg).
    passed : bool
        No failed image and every |error| ≤ tolerance.
    out_dir : pathlib.Path
        Where accuracy.csv, accuracy.json and accuracy.png were written.
    """

    table: pd.DataFrame
    n: int
    n_failed: int
    bias_deg: float
    rms_deg: float
    max_abs_error_deg: float
    scale_error: float
    offset_deg: float
    fit_residual_rms_deg: float
    u95_deg: float
    coverage_factor: float
    reference_std_deg: float
    tolerance_deg: float
    passed: bool
    out_dir: Path

    def summary(self) -> dict:
        """The accuracy.json contents."""
        d = {k: v for k, v in asdict(self).items() if k not in ("table", "out_dir")}
        d["u95_method"] = "k * sqrt(rms_deg^2 + reference_std_deg^2), k = Student t 0.975 with n - 1 dof"
        return d


def _fail(path, line, why):
    raise ReferenceTableError(f"{path}, line {line}: {why}")


def read_reference_table(folder) -> pd.DataFrame:
    """Read and validate ``reference.csv`` of a check folder.

    Returns
    -------
    pandas.DataFrame
        Columns ``image`` (str) and ``reference_angle_deg`` (float), table order.

    Raises
    ------
    ReferenceTableError
        The file is missing or unreadable, lacks a column, has fewer than three rows,
        a non-numeric angle, a duplicate image name or an image that does not exist
        (the message names the CSV line number).
    """
    folder = Path(folder)
    path = folder / "reference.csv"
    if not path.exists():
        raise ReferenceTableError(f"{path}: no reference table (expected image,reference_angle_deg)")
    # its size before it is read; a folder, a named pipe or a device refused by name
    raw = read_text_bytes(path, what="a reference table", error=ReferenceTableError)
    try:
        text = decode_utf8(raw, name=path, error=ReferenceTableError, what="the table")
        sep = csv_delimiter(text.split("\n", 1)[0], ("image", "reference_angle_deg"))
        rows = list(csv.reader(io.StringIO(text, newline=""), delimiter=sep))
    except (OSError, csv.Error) as exc:
        raise ReferenceTableError(f"{path}: cannot read ({exc})") from None
    if not rows:
        raise ReferenceTableError(f"{path}: empty file")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in ("image", "reference_angle_deg") if c not in header]
    if missing:
        raise ReferenceTableError(f"{path}: missing column(s) {', '.join(missing)} (header is {','.join(header)})")
    ii, ia = header.index("image"), header.index("reference_angle_deg")
    body = [(n, r) for n, r in enumerate(rows[1:], start=2) if any(c.strip() for c in r)]
    if len(body) < 3:
        raise ReferenceTableError(f"{path}: {len(body)} row(s); need at least 3 (the reference image and two more)")
    seen, names, angles = {}, [], []
    for line, r in body:
        if len(r) != len(header):
            _fail(path, line, f"expected {len(header)} fields, got {len(r)}")
        name, text = r[ii].strip(), r[ia].strip()
        if not name:
            _fail(path, line, "empty image name")
        if name in seen:
            _fail(path, line, f"duplicate image {name!r} (first on line {seen[name]})")
        seen[name] = line
        try:
            angle = float(text)
        except ValueError:
            _fail(path, line, f"reference_angle_deg {text!r} is not a number")
        if not math.isfinite(angle):
            _fail(path, line, f"reference_angle_deg {text!r} is not finite")
        if not (folder / name).is_file():
            _fail(path, line, f"image {name!r} not found in {folder}")
        names.append(name)
        angles.append(angle)
    return pd.DataFrame({"image": names, "reference_angle_deg": angles})


def load_spec(path) -> AccuracySpec:
    """Read a check spec (TOML; format in the module docstring).

    Raises
    ------
    ReferenceTableError
        The file is missing, not TOML, has unknown keys or a bad value (named).
    """
    from ..resources import SPECS, named_file

    p = named_file(path, SPECS, error=ReferenceTableError, what="spec")  # a path, or a ready spec's name
    d = read_toml(p, what="an accuracy-check spec (TOML)", error=ReferenceTableError)
    unknown = set(d) - {"description", "tolerance_deg", "reference_std_deg", "correction", "markers"}
    if unknown:
        raise ReferenceTableError(f"{p}: unknown key(s) {', '.join(sorted(unknown))}")
    for key in ("tolerance_deg", "reference_std_deg"):
        v = d.get(key, 0.0 if key == "reference_std_deg" else DEFAULT_TOLERANCE_DEG)
        check_number(v, name=f"{p}: {key}", error=ReferenceTableError, low=0, low_open=key == "tolerance_deg",
                     unit="degrees")
    try:
        settings = MeasureSettings.from_dict(d["markers"]) if "markers" in d else None
    except (VisionTorsionError, TypeError) as exc:
        raise ReferenceTableError(f"{p}: [markers]: {exc}") from None
    corr = d.get("correction")
    if corr is not None:
        corr = str((p.parent / corr).resolve()) if not Path(corr).is_absolute() else corr
    return AccuracySpec(
        tolerance_deg=float(d.get("tolerance_deg", DEFAULT_TOLERANCE_DEG)),
        reference_std_deg=float(d.get("reference_std_deg", 0.0)),
        settings=settings,
        correction=corr,
        description=str(d.get("description", "")),
    )


def _statistics(ref, meas, n_failed, tolerance, reference_std):
    err = meas - ref
    n = int(err.size)
    rms = float(np.sqrt(np.mean(err**2)))
    slope, offset = np.polyfit(ref, meas, 1)
    resid = meas - (slope * ref + offset)
    k = float(stats.t.ppf(0.975, n - 1))
    max_abs = float(np.max(np.abs(err)))
    return dict(
        n=n,
        n_failed=n_failed,
        bias_deg=float(np.mean(err)),
        rms_deg=rms,
        max_abs_error_deg=max_abs,
        scale_error=float(slope - 1.0),
        offset_deg=float(offset),
        fit_residual_rms_deg=float(np.sqrt(np.mean(resid**2))),
        u95_deg=k * math.hypot(rms, reference_std),
        coverage_factor=k,
        reference_std_deg=float(reference_std),
        tolerance_deg=float(tolerance),
        passed=bool(n_failed == 0 and max_abs <= tolerance),
    )


def _plot(path, table, tolerance):
    # matplotlib only when a plot is drawn: check-accuracy starts faster
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..plotting import save_figure

    ok = table[table["status"] == "ok"]
    fig = Figure(figsize=(7, 4), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    lo = float(table["reference_angle_deg"].min()) - 1
    hi = float(table["reference_angle_deg"].max()) + 1
    ax.axhspan(-tolerance, tolerance, color="tab:green", alpha=0.15, label=f"±{tolerance:g}° tolerance")
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.errorbar(
        ok["reference_angle_deg"],
        ok["error_deg"],
        yerr=ok["angle_std_deg"],
        fmt="o",
        ms=4,
        capsize=2,
        label="error (±1σ)",
    )
    bad = ok[ok["error_deg"].abs() > tolerance]
    if len(bad):
        ax.plot(bad["reference_angle_deg"], bad["error_deg"], "rx", ms=8, label="outside tolerance")
    ax.set_xlim(lo, hi)
    ax.set_xlabel("reference angle (deg, CCW as displayed)")
    ax.set_ylabel("measured − reference (deg)")
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    save_figure(fig, path)


def check_accuracy(
    folder,
    *,
    out_dir=None,
    tolerance_deg: float | None = None,
    spec=None,
    settings: MeasureSettings | None = None,
    correction=None,
    progress: bool = False,
) -> AccuracyResult:
    """Check the angle measurement against the reference angles of a folder.

    Parameters
    ----------
    folder : str or os.PathLike
        Holds the images and ``reference.csv`` (see :func:`read_reference_table`).
    out_dir : str or os.PathLike, optional
        Output folder; ``FOLDER/results`` by default.
    tolerance_deg : float, optional
        Pass band ±tolerance (deg); the spec's, else 0.02° (the paper's).
    spec : path or AccuracySpec, optional
        A ready check (see the module docstring); explicit arguments override it.
    settings : MeasureSettings, optional
        How markers are found; the spec's, else defaults. Its ``correction`` path
        is used when no other correction is given.
    correction : PlaneCorrection or path, optional
        Plane/lens correction applied to both pairs of every angle.
    progress : bool
        Show a progress bar.

    Returns
    -------
    AccuracyResult

    Raises
    ------
    ReferenceTableError
        Bad reference table or spec (see :func:`read_reference_table`,
        :func:`load_spec`), a non-positive tolerance, or fewer than two images
        measured besides the reference.
    ImageReadError, MarkerError, CalibrationError
        The reference image is unusable, or the correction cannot be loaded.
    """
    folder = Path(folder)
    if spec is not None and not isinstance(spec, AccuracySpec):
        spec = load_spec(spec)
    spec = spec or AccuracySpec()
    tol = check_number(spec.tolerance_deg if tolerance_deg is None else tolerance_deg, name="tolerance",
                       error=ReferenceTableError, low=0, low_open=True, unit="degrees")
    settings = settings or spec.settings or MeasureSettings()
    corr = load_correction(correction if correction is not None else (spec.correction or settings.correction))
    table = read_reference_table(folder)
    out = output_folder(folder, out_dir)
    if same_folder(out, folder):
        raise OutputError(
            f"{out}: the output folder cannot be the image folder itself (results "
            "written among the images would be taken for images); use a subfolder "
            "such as results/"
        )
    check_output_dir(out, replaces=["accuracy.csv", "accuracy.json", "accuracy.png"])
    names, refs = list(table["image"]), table["reference_angle_deg"].to_numpy()
    ref_pair = measure_pair(folder / names[0], settings=settings, name=f"reference {names[0]}")
    _, angles, reasons = measure_sequence(
        ref_pair,
        [(folder / name, name) for name in names[1:]],
        settings=settings,
        correction=corr,
        progress=progress,
        predictions=refs[1:] - refs[0],
    )
    rows = [
        dict(
            image=names[0],
            reference_angle_deg=refs[0],
            measured_angle_deg=refs[0],
            error_deg=0.0,
            angle_std_deg=np.nan,
            status="reference",
        )
    ]
    for name, ref, ang, why in zip(names[1:], refs[1:], angles, reasons):
        row = dict(
            image=name,
            reference_angle_deg=ref,
            measured_angle_deg=np.nan,
            error_deg=np.nan,
            angle_std_deg=np.nan,
            status=f"failed: {why}",
        )
        if ang is not None:
            measured = refs[0] + ang.angle_deg
            row.update(
                measured_angle_deg=measured, error_deg=measured - ref, angle_std_deg=ang.angle_std_deg, status="ok"
            )
        rows.append(row)
    frame = pd.DataFrame(rows, columns=ACCURACY_COLUMNS)
    ok = frame[frame["status"] == "ok"]
    n_failed = len(frame) - 1 - len(ok)
    if len(ok) < 2:
        raise ReferenceTableError(
            f"{folder}: only {len(ok)} image(s) measured besides the reference; need at least 2 "
            f"({n_failed} failed: {'; '.join(r for r in reasons if r)})"
        )
    figures = _statistics(
        ok["reference_angle_deg"].to_numpy(), ok["measured_angle_deg"].to_numpy(), n_failed, tol, spec.reference_std_deg
    )
    result = AccuracyResult(table=frame, out_dir=out, **figures)
    summary = result.summary()
    summary.update(folder=str(folder), correction=None if corr is None else corr.method, description=spec.description)
    with output_set():
        write_csv(out / "accuracy.csv", frame)
        write_json(out / "accuracy.json", summary)
        _plot(out / "accuracy.png", frame, tol)
    return result
