"""A session folder as a whole: ``session.toml`` + ``manifest.csv`` + the images.

:func:`load_session` is what ``process`` calls before measuring anything: it
validates the configuration (:mod:`.config`), the manifest and every image file
(:mod:`.manifest`), and resolves what the rows need (measurement settings, torques).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import SessionError
from ..images import IMAGE_SUFFIXES
from ..settings import MeasureSettings
from .config import CONFIG_NAME, SessionConfig, load_config
from .manifest import MANIFEST_NAME, Manifest, ManifestRow, load_manifest
from .torque import TorqueValue, couple_torque

__all__ = ["Session", "load_session", "unlisted_images"]


@dataclass(frozen=True)
class Session:
    """A validated session folder.

    Attributes
    ----------
    folder : pathlib.Path
    config : SessionConfig
    manifest : Manifest
    """

    folder: Path
    config: SessionConfig
    manifest: Manifest

    @property
    def settings(self) -> MeasureSettings:
        """Measurement settings, with a relative ``correction`` path made absolute."""
        markers = self.config.markers
        if markers.correction is None:
            return markers
        return replace(markers, correction=str((self.folder / markers.correction).resolve()))

    def torque(self, row: ManifestRow) -> TorqueValue:
        """Torque of `row`: the measured ``torque_nm`` if given, else from the weights.

        A measured torque has no part known to be common to all images, so its
        ``torque_common_std_nm`` is NaN (unknown).
        """
        if row.torque_nm is not None:
            return TorqueValue(row.torque_nm, row.torque_std_nm, math.nan)
        return couple_torque(row.mass_kg, row.phase, self.config.rig)


def load_session(session_dir, *, check_files: bool = True, missing: str = "error") -> Session:
    """Read and validate a session folder.

    Parameters
    ----------
    session_dir : str or os.PathLike
        Folder holding ``session.toml``, ``manifest.csv`` and the images.
    check_files : bool
        Check that every image exists and can be opened (see :func:`load_manifest`).
    missing : {"error", "pending"}
        Whether an image that does not exist yet is a problem or a pending row
        (see :func:`load_manifest`).

    Returns
    -------
    Session

    Raises
    ------
    SessionError
        The folder does not exist, or session.toml is missing or invalid (every
        problem listed), or ``markers.correction`` names a missing file.
    ManifestError
        manifest.csv is missing or has problems (every problem listed with its CSV
        line number).
    """
    folder = Path(session_dir)
    if not folder.is_dir():
        raise SessionError(f"{folder}: no such folder (expected a session folder with "
                           f"{CONFIG_NAME} and {MANIFEST_NAME})")
    config = load_config(folder / CONFIG_NAME)
    if config.markers.correction is not None:
        corr = folder / config.markers.correction
        if not corr.is_file():
            raise SessionError(f"{folder / CONFIG_NAME}: markers.correction: no such file "
                               f"{corr}")
    manifest = load_manifest(folder / MANIFEST_NAME, check_files=check_files, missing=missing)
    from .plausibility import check_session_numbers

    check_session_numbers(config, manifest, config_path=folder / CONFIG_NAME)  # unit slips
    return Session(folder=folder, config=config, manifest=manifest)


def unlisted_images(session: Session, *, exclude=()) -> list[str]:
    """Image files in the session folder (and a bound camera folder) that no
    manifest row names: a shot saved under a wrong name, an extra shot.

    Parameters
    ----------
    session : Session
    exclude : sequence of path-like
        Folders not to look into (the output folder); hidden folders are skipped.

    Returns
    -------
    list of str
        Paths relative to the session folder (``/`` separators), then absolute
        paths of unbound files of the camera folder, each in name order.
    """
    skip = {Path(p).resolve() for p in exclude}
    named = {row.image for row in session.manifest.rows}
    bound = {Path(p).resolve() for p in session.manifest.sources.values()}
    found = []
    # os.walk, not rglob: hidden and excluded folders are not entered at all, and only
    # the files no row names are resolved (a session holds thousands of named images)
    for here, folders, files in os.walk(session.folder):
        folders[:] = [f for f in folders
                      if not f.startswith(".") and (Path(here) / f).resolve() not in skip]
        # the named files are told by their names alone, with string operations: a
        # Path per file cost a run of the 444-image demo 4 ms after its last image
        base = Path(here).relative_to(session.folder)
        prefix = "" if base == Path(".") else base.as_posix() + "/"
        for name in files:
            if (name.startswith(".") or prefix + name in named
                    or os.path.splitext(name)[1].lower() not in IMAGE_SUFFIXES):
                continue
            path = Path(here) / name
            if path.is_file() and path.resolve() not in bound:
                found.append(base / name)
    out = [rel.as_posix() for rel in sorted(found)]
    from .binding import load_binding

    binding = load_binding(session.folder)
    if binding is not None and binding.camera_dir.is_dir():
        used = set(binding.images.values()) | set(binding.skipped)
        inside = {(session.folder / r).resolve() for r in out}
        out += [str(p) for p in sorted(binding.camera_dir.iterdir())
                if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and p.name not in used
                and p.resolve() not in inside]
    return out
