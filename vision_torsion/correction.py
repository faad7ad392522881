"""A saved plane correction: image pixels to disk-plane coordinates, applied in the core.

Applying a correction is part of measuring an angle (:mod:`vision_torsion.angle`
applies it to both marker pairs; :class:`~vision_torsion.settings.MeasureSettings`
names its file), so it lives here, beside the settings and the angle; computing one
(self-calibration, a target) is :mod:`vision_torsion.calibration`'s work.

A camera that is not square to the torque disk sees the disk plane through a
homography, and a lens adds radial distortion. :class:`PlaneCorrection` undoes both:

1. radial distortion is removed first (optional): the image point x_d is the
   undistorted point u moved radially about the distortion centre c,
   ``x_d = c + (u - c)(1 + k1·ρ²)`` with ρ = |u - c| / f (the model of
   :class:`vision_torsion.synthetic.geometry.CameraMapping` and OpenCV's first radial
   term with f = fx); u is found by fixed-point iteration;
2. the 3x3 homography H maps the undistorted point to the disk plane,
   ``(X, Y, W)ᵀ = H (u_x, u_y, 1)ᵀ``, X/W and Y/W.

Coordinates in and out are (x, y) pixels, origin at the centre of the top-left pixel,
y downwards. The disk plane is fixed only up to a similarity (a similarity does not
change angles); calibrations normalise it with
:func:`vision_torsion.calibration.anchoring.normalised` so that the correction is
close to the identity near the target (same scale, no turn).

Centre covariances are propagated to first order: Σ' = J Σ Jᵀ with J the 2x2
Jacobian of the whole correction at the point.

File format (TOML or JSON, chosen by the suffix; the same keys in both)::

    format = "vision-torsion plane correction"
    version = 1
    method = "self-calibration"          # or "target", free text
    homography = [[h00, h01, h02], [h10, h11, h12], [h20, h21, h22]]

    [distortion]                         # optional table
    k1 = -0.02
    centre_x_px = 699.5
    centre_y_px = 499.5
    focal_length_px = 5000.0

    [info]                               # optional, free: how the fit went
    ...
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import tomli_w

from .errors import CalibrationError
from .fileio import atomic_write_text
from .pair import PairMeasurement
from .textfiles import decode_utf8, read_text_bytes, read_toml
from .validate import check_number

__all__ = ["PlaneCorrection", "load_correction", "check_suffix", "FORMAT_NAME", "FORMAT_VERSION"]

FORMAT_NAME = "vision-torsion plane correction"
FORMAT_VERSION = 1
_UNDISTORT_ITERATIONS = 30


@dataclass(frozen=True, eq=False)
class PlaneCorrection:
    """Image → disk-plane mapping: radial undistortion, then a homography.

    Parameters
    ----------
    homography : (3, 3) array_like
        Maps undistorted image points (px) to the disk plane; scaled so H[2, 2] = 1.
    k1 : float
        First radial distortion coefficient (0: none).
    centre : (float, float), optional
        Distortion centre (x, y) in px; needed when k1 ≠ 0.
    focal_length_px : float, optional
        The f of ρ = |u - c| / f; needed when k1 ≠ 0.
    method : str
        How it was obtained (``"self-calibration"``, ``"target"``, ...).
    info : dict
        Free JSON-safe details of the fit (written to the file's ``[info]`` table).

    Raises
    ------
    CalibrationError
        The homography is not a finite invertible 3x3 matrix, or k1 ≠ 0 without a
        centre and a positive focal length.

    Examples
    --------
    >>> c = PlaneCorrection(np.diag([2.0, 2.0, 1.0]))
    >>> X, Y, cov = c.apply(1.0, 3.0, np.eye(2) * 0.01)
    >>> float(X), float(Y), cov.tolist()
    (2.0, 6.0, [[0.04, 0.0], [0.0, 0.04]])
    """

    homography: np.ndarray
    k1: float = 0.0
    centre: tuple[float, float] | None = None
    focal_length_px: float | None = None
    method: str = "manual"
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        H = np.array(self.homography, dtype=np.float64)
        if H.shape != (3, 3) or not np.all(np.isfinite(H)):
            raise CalibrationError(f"homography must be a finite 3x3 matrix, got shape {H.shape}")
        if abs(H[2, 2]) < 1e-300 or abs(np.linalg.det(H / H[2, 2])) < 1e-12:
            raise CalibrationError("homography is singular")
        H = H / H[2, 2]
        H.setflags(write=False)
        object.__setattr__(self, "homography", H)
        k1 = check_number(self.k1, name="k1", error=CalibrationError)
        object.__setattr__(self, "k1", k1)
        if k1 != 0.0:
            if self.centre is None or self.focal_length_px is None or not float(self.focal_length_px) > 0:
                raise CalibrationError("k1 ≠ 0 needs the distortion centre and a positive focal_length_px")
        if self.centre is not None:
            object.__setattr__(self, "centre", (float(self.centre[0]), float(self.centre[1])))
        if self.focal_length_px is not None:
            object.__setattr__(self, "focal_length_px", float(self.focal_length_px))

    def __eq__(self, other):
        """Same mapping: homography, distortion and method equal (``info`` is ignored)."""
        if not isinstance(other, PlaneCorrection):
            return NotImplemented
        return (
            np.array_equal(self.homography, other.homography)
            and (self.k1, self.centre, self.focal_length_px, self.method)
            == (other.k1, other.centre, other.focal_length_px, other.method)
        )

    __hash__ = None

    # -- mapping -----------------------------------------------------------------------
    def undistort(self, x, y):
        """Remove radial distortion: image (px) → undistorted image (px)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if self.k1 == 0.0:
            return x, y
        cx, cy = self.centre
        dx, dy = x - cx, y - cy
        ux, uy = dx, dy
        f2 = self.focal_length_px**2
        for _ in range(_UNDISTORT_ITERATIONS):
            g = 1.0 + self.k1 * (ux * ux + uy * uy) / f2
            ux, uy = dx / g, dy / g
        return cx + ux, cy + uy

    def jacobian(self, x, y):
        """Jacobian (..., 2, 2) of the whole correction at image points (px), and the mapped points X, Y."""
        ux, uy = self.undistort(x, y)
        H = self.homography
        w = H[2, 0] * ux + H[2, 1] * uy + H[2, 2]
        X = (H[0, 0] * ux + H[0, 1] * uy + H[0, 2]) / w
        Y = (H[1, 0] * ux + H[1, 1] * uy + H[1, 2]) / w
        Jh = np.empty(np.shape(ux) + (2, 2))
        Jh[..., 0, 0] = (H[0, 0] - X * H[2, 0]) / w
        Jh[..., 0, 1] = (H[0, 1] - X * H[2, 1]) / w
        Jh[..., 1, 0] = (H[1, 0] - Y * H[2, 0]) / w
        Jh[..., 1, 1] = (H[1, 1] - Y * H[2, 1]) / w
        if self.k1 == 0.0:
            return Jh, X, Y
        # the undistortion's Jacobian is the inverse of the distortion's at u
        cx, cy = self.centre
        dx, dy = ux - cx, uy - cy
        f2 = self.focal_length_px**2
        g = 1.0 + self.k1 * (dx * dx + dy * dy) / f2
        Jd = np.empty_like(Jh)
        Jd[..., 0, 0] = g + 2 * self.k1 * dx * dx / f2
        Jd[..., 0, 1] = Jd[..., 1, 0] = 2 * self.k1 * dx * dy / f2
        Jd[..., 1, 1] = g + 2 * self.k1 * dy * dy / f2
        return Jh @ np.linalg.inv(Jd), X, Y

    def to_disk(self, x, y):
        """Image points (px) → disk-plane points; arrays of any matching shape."""
        _, X, Y = self.jacobian(x, y)
        return X, Y

    def apply(self, x, y, cov=None):
        """Map one or more centres and propagate their covariances.

        Parameters
        ----------
        x, y : float or array_like
            Image coordinates (px), origin at the centre of the top-left pixel, y down.
        cov : array_like, optional
            Covariances (..., 2, 2) in px² matching `x`; not changed.

        Returns
        -------
        X, Y : numpy.ndarray
            Disk-plane coordinates.
        cov : numpy.ndarray or None
            J Σ Jᵀ (first-order propagation), or None when `cov` is None.
        """
        J, X, Y = self.jacobian(x, y)
        if cov is None:
            return X, Y, None
        S = np.asarray(cov, dtype=np.float64)
        return X, Y, J @ S @ np.swapaxes(J, -1, -2)

    def apply_pair(self, pair: PairMeasurement) -> PairMeasurement:
        """The pair with both centres (and their covariances) on the disk plane.

        Radii and other marker fields are kept as measured in the image.
        """
        return replace(pair, first=self._apply_marker(pair.first), second=self._apply_marker(pair.second))

    def _apply_marker(self, m):
        cov = m.cov
        if not np.isfinite(m.xy_cov_px2):
            # an unknown correlation is taken as none; unknown variances stay NaN
            cov[0, 1] = cov[1, 0] = 0.0
        X, Y, C = self.apply(m.x_px, m.y_px, cov)
        return replace(
            m,
            x_px=float(X),
            y_px=float(Y),
            x_std_px=float(np.sqrt(C[0, 0])),
            y_std_px=float(np.sqrt(C[1, 1])),
            xy_cov_px2=float(C[0, 1]),
        )

    # -- files -------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The file contents as a plain dict (see the module docstring)."""
        d = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "method": self.method,
            "homography": [[float(v) for v in row] for row in self.homography],
        }
        if self.k1 != 0.0 or self.centre is not None:
            d["distortion"] = {"k1": self.k1}
            if self.centre is not None:
                d["distortion"].update(centre_x_px=self.centre[0], centre_y_px=self.centre[1])
            if self.focal_length_px is not None:
                d["distortion"]["focal_length_px"] = self.focal_length_px
        if self.info:
            d["info"] = _plain(self.info)
        return d

    def save(self, path) -> Path:
        """Write atomically as TOML (``.toml``) or JSON (``.json``); returns the path.

        Raises
        ------
        CalibrationError
            The suffix is neither.
        """
        p = Path(path)
        kind = check_suffix(p)
        d = self.to_dict()
        text = tomli_w.dumps(d) if kind == "toml" else json.dumps(d, indent=2) + "\n"
        return atomic_write_text(p, text)

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "correction") -> "PlaneCorrection":
        """Build from :meth:`to_dict` output; errors name `source` and the field."""
        if not isinstance(d, dict):
            raise CalibrationError(f"{source}: expected a table of fields")
        if d.get("format") != FORMAT_NAME:
            raise CalibrationError(f"{source}: field 'format' must be {FORMAT_NAME!r}, got {d.get('format')!r}")
        if d.get("version") != FORMAT_VERSION:
            raise CalibrationError(
                f"{source}: field 'version' must be {FORMAT_VERSION}, got {d.get('version')!r}"
            )
        unknown = set(d) - {"format", "version", "method", "homography", "distortion", "info"}
        if unknown:
            raise CalibrationError(f"{source}: unknown field(s) {', '.join(sorted(unknown))}")
        H = _matrix(d.get("homography"), source)
        dist = d.get("distortion", {})
        if not isinstance(dist, dict):
            raise CalibrationError(f"{source}: field 'distortion' must be a table")
        bad = set(dist) - {"k1", "centre_x_px", "centre_y_px", "focal_length_px"}
        if bad:
            raise CalibrationError(f"{source}: unknown field(s) distortion.{', distortion.'.join(sorted(bad))}")
        vals = {k: _number(dist[k], f"distortion.{k}", source) for k in dist}
        centre = None
        if "centre_x_px" in vals or "centre_y_px" in vals:
            missing = [k for k in ("centre_x_px", "centre_y_px") if k not in vals]
            if missing:
                raise CalibrationError(f"{source}: field 'distortion.{missing[0]}' is missing")
            centre = (vals["centre_x_px"], vals["centre_y_px"])
        try:
            return cls(
                H,
                k1=vals.get("k1", 0.0),
                centre=centre,
                focal_length_px=vals.get("focal_length_px"),
                method=str(d.get("method", "manual")),
                info=dict(d.get("info", {})),
            )
        except CalibrationError as exc:
            raise CalibrationError(f"{source}: {exc}") from None

    @classmethod
    def load(cls, path) -> "PlaneCorrection":
        """Read a correction written by :meth:`save` (TOML or JSON by suffix).

        Raises
        ------
        CalibrationError
            The file is missing or unreadable, not valid TOML/JSON, or a field is
            missing or wrong (the message names the file and the field).
        """
        p = Path(path)
        kind = check_suffix(p)
        if kind == "toml":
            d = read_toml(p, what="a plane correction file", error=CalibrationError)
        else:
            # its size before it is read, as the TOML form's (a named pipe refused, never waited on)
            raw = read_text_bytes(p, what="a plane correction file", error=CalibrationError)
            text = decode_utf8(raw, name=p, error=CalibrationError, what="the correction file")
            try:
                d = json.loads(text)
            except json.JSONDecodeError as exc:
                raise CalibrationError(f"{p}: not valid JSON ({exc})", reason="bad_json") from None
        return cls.from_dict(d, source=str(p))


def load_correction(correction) -> PlaneCorrection | None:
    """A PlaneCorrection from a path, an existing correction, or None (no correction)."""
    if correction is None or isinstance(correction, PlaneCorrection):
        return correction
    return PlaneCorrection.load(correction)


def check_suffix(p: Path) -> str:
    """``"toml"`` or ``"json"`` from a correction file's suffix; another is a CalibrationError."""
    suffix = p.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise CalibrationError(f"{p}: a correction file must end in .toml or .json")
    return suffix[1:]


def _number(v, name, source) -> float:
    return check_number(v, name=f"{source}: field '{name}'", error=CalibrationError)


def _matrix(v, source) -> np.ndarray:
    if v is None:
        raise CalibrationError(f"{source}: field 'homography' is missing")
    if not isinstance(v, list) or len(v) != 3 or any(not isinstance(r, list) or len(r) != 3 for r in v):
        raise CalibrationError(f"{source}: field 'homography' must be a 3x3 list of numbers")
    return np.array([[_number(x, f"homography[{i}][{j}]", source) for j, x in enumerate(r)] for i, r in enumerate(v)])


def _plain(obj):
    """JSON/TOML-safe copy of `obj` (numpy scalars and arrays to Python, None dropped)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
