"""Folders of synthetic images ready for the other commands.

``write_accuracy_folder`` writes an accuracy-check folder: images, ``reference.csv``
(``image,reference_angle_deg``; the first row is the reference image at 0°, angles
counter-clockwise positive as displayed) and ``truth.csv`` with every marker's true
centre in image coordinates (the projected centre under tilt) and on the disk plane.

Images are written atomically, one by one, so an interrupted run leaves only
complete files; the tables are written last.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..errors import SceneError
from ..fileio import atomic_write_bytes, write_csv
from ..images import write_image
from ..progress import track
from .render import render
from .scene import Scene, check_markers_in_frame

__all__ = ["write_accuracy_folder", "write_rendered", "truth_row"]


def truth_row(image_name: str, rendered, **extra) -> dict:
    """One row of a truth table: image, true angle and every marker's true centre (px)."""
    row = {"image": image_name, "true_angle_deg": rendered.angle_deg, **extra}
    for k, ((x, y), (X, Y)) in enumerate(zip(rendered.centres, rendered.centres_disk), start=1):
        row[f"marker{k}_x_px"] = float(x)
        row[f"marker{k}_y_px"] = float(y)
        row[f"marker{k}_disk_x_px"] = float(X)
        row[f"marker{k}_disk_y_px"] = float(Y)
    return row


def _suffix(scene: Scene) -> str:
    return ".jpg" if scene.noise.jpeg_quality else ".png"


def write_rendered(path, rendered, scene: Scene) -> None:
    """Write a rendered image atomically: JPEG scenes as the very bytes the renderer
    compressed (no second compression), others as lossless PNG."""
    if rendered.jpeg_bytes is not None:
        atomic_write_bytes(path, rendered.jpeg_bytes)
    else:
        write_image(path, rendered.image, bit_depth=scene.image.bit_depth)


def write_accuracy_folder(
    scene: Scene, out_dir, *, angles_deg=None, seed: int = 0, progress: bool = False
) -> Path:
    """Render an accuracy-check folder.

    Parameters
    ----------
    scene : Scene
        What to render.
    out_dir : str or os.PathLike
        Folder to create or fill (existing files of the same names are replaced).
    angles_deg : sequence of float, optional
        Rotations to render (deg, counter-clockwise as displayed); the scene's
        ``[sweep] angles_deg`` by default. A reference image at 0° is always first.
    seed : int
        Base seed; image i uses ``seed + i``.
    progress : bool
        Show a progress bar.

    Returns
    -------
    pathlib.Path
        The folder.

    Raises
    ------
    SceneError
        A marker leaves the frame at one of the angles (checked before anything is
        written).
    """
    angles = list(scene.sweep.angles_deg if angles_deg is None else angles_deg)
    angles = [float(a) for a in angles]
    if not angles or angles[0] != 0.0:
        angles.insert(0, 0.0)
    if len(angles) < 2:
        raise SceneError("an accuracy folder needs at least one angle besides the reference")
    for a in angles:
        check_markers_in_frame(scene, a, where=scene.name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    refs, truths = [], []
    for i, a in enumerate(track(angles, desc="rendering", unit="image", enabled=progress)):
        name = f"{'reference' if i == 0 else f'img_{i:03d}'}{_suffix(scene)}"
        r = render(scene, a, seed=seed + i)
        write_rendered(out / name, r, scene)
        refs.append({"image": name, "reference_angle_deg": a})
        truths.append(truth_row(name, r))
    write_csv(out / "truth.csv", pd.DataFrame(truths))
    write_csv(out / "reference.csv", pd.DataFrame(refs))
    return out
