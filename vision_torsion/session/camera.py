"""A camera's folder, read and never written: its image files in capture order.

A camera (or its tethering software) writes ``IMG_0001.JPG, IMG_0002.JPG, ...``
into a folder. :func:`list_camera_files` lists the files directly in it, in the
order they were taken:

- ``by="time"``: the capture time, from the EXIF ``DateTimeOriginal`` tag (with
  ``SubSecTimeOriginal`` when present) read with Pillow, else the file's
  modification time; ties broken by natural name order. Cameras number files in
  the order they are taken, but the counter wraps (IMG_9999 → IMG_0001) and two
  cameras or card readers may interleave: the time is the safer default.
- ``by="name"``: natural name order (IMG_2 < IMG_10).

What is not a photograph is set aside with a reason, never measured: files whose
name is not an image type (sidecars such as ``.THM`` or ``.XMP``), files larger than
an image file may be (:data:`~vision_torsion.images.MAX_IMAGE_FILE_BYTES`: refused
without being read, as the image reader does), and byte-for-byte copies of an
earlier file (the same photograph saved twice is not a new shot).
Subfolders are not looked into.
"""

from __future__ import annotations

import logging
import os
import stat
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from ..errors import ImageReadError, SessionError
from ..images import IMAGE_SUFFIXES, read_image_bytes
from ..measure import natural_key

__all__ = ["CameraFile", "CameraListing", "list_camera_files", "capture_time", "ORDERS"]

logger = logging.getLogger(__name__)

#: How camera files can be ordered.
ORDERS = ("time", "name")
_EXIF_IFD = 0x8769
_DATETIME_ORIGINAL = 36867
_SUBSEC_ORIGINAL = 37521


@dataclass(frozen=True)
class CameraFile:
    """One image file of a camera folder.

    Attributes
    ----------
    name : str
        File name inside the camera folder.
    path : pathlib.Path
    time : float
        Capture time, seconds since the epoch (local time of the camera for EXIF).
    time_source : str
        "exif" or "mtime".
    """

    name: str
    path: Path
    time: float
    time_source: str


@dataclass(frozen=True)
class CameraListing:
    """What :func:`list_camera_files` found.

    Attributes
    ----------
    files : tuple of CameraFile
        The photographs, in capture order.
    ignored : tuple of (str, str)
        (file name, why) of every file set aside: not an image, or a copy.
    """

    files: tuple[CameraFile, ...]
    ignored: tuple[tuple[str, str], ...]


def capture_time(path) -> tuple[float, str]:
    """When an image was taken: (seconds since the epoch, "exif" or "mtime").

    The EXIF ``DateTimeOriginal`` (and ``SubSecTimeOriginal``) of JPEG and TIFF
    files, else the file's modification time (what a PNG from tethering software
    or a copy from a card keeps, usually the time it was written).

    Raises
    ------
    OSError
        The file cannot be stat'ed (it vanished).
    """
    path = Path(path)
    if path.suffix.lower() in (".jpg", ".jpeg", ".tif", ".tiff"):
        try:
            from PIL import Image

            with Image.open(path) as im:
                exif = im.getexif().get_ifd(_EXIF_IFD)
            text = exif.get(_DATETIME_ORIGINAL)
            if text:
                when = datetime.strptime(str(text).strip("\0 "), "%Y:%m:%d %H:%M:%S").timestamp()
                sub = str(exif.get(_SUBSEC_ORIGINAL) or "").strip("\0 ")
                if sub.isdigit():
                    when += int(sub) / 10 ** len(sub)
                return when, "exif"
        except Exception as exc:  # noqa: BLE001 - a broken EXIF block is no reason to stop
            logger.debug("%s: no usable EXIF capture time (%s)", path, exc)
    return os.stat(path).st_mtime, "mtime"


def list_camera_files(camera_dir, *, by: str = "time") -> CameraListing:
    """The photographs in a camera folder, in capture order (see the module docstring).

    Parameters
    ----------
    camera_dir : str or os.PathLike
        The camera's folder; only read.
    by : {"time", "name"}
        Order by capture time (EXIF, then file time) or by natural name order.

    Returns
    -------
    CameraListing

    Raises
    ------
    SessionError
        The folder does not exist, or `by` is unknown.
    """
    import xxhash

    if by not in ORDERS:
        raise SessionError(f"by must be one of {', '.join(ORDERS)}, got {by!r}")
    folder = Path(camera_dir)
    if not folder.is_dir():
        raise SessionError(f"{folder}: no such folder (expected the camera's folder of images)")
    ignored, found = [], []
    for path in sorted(folder.iterdir(), key=lambda p: natural_key(p.name)):
        if path.is_dir():
            continue
        if path.suffix.lower() not in IMAGE_SUFFIXES:
            ignored.append((path.name, f"not an image file (expected {', '.join(IMAGE_SUFFIXES)}); "
                                       "not bound"))
            continue
        try:
            if not stat.S_ISREG(os.stat(path).st_mode):  # reading a named pipe would wait for ever
                ignored.append((path.name, "not a regular file (a named pipe or a device); not bound"))
                continue
            when, source = capture_time(path)
        except OSError as exc:
            ignored.append((path.name, f"cannot be read ({exc.strerror or exc}); not bound"))
            continue
        found.append(CameraFile(path.name, path, when, source))
    # a copy is the later of two identical files (by capture time, then the shorter name)
    originals: dict[str, CameraFile] = {}
    for f in sorted(found, key=lambda f: (f.time, len(f.name), natural_key(f.name))):
        try:  # the image reader's limit, checked before the file is read
            h = xxhash.xxh3_128_hexdigest(read_image_bytes(f.path, signature=False))
        except ImageReadError as exc:  # too large, or cannot be read
            ignored.append((f.name, f"{str(exc).removeprefix(f'{f.path}: ')}; not bound"))
            continue
        if h in originals:
            ignored.append((f.name, f"the same bytes as {originals[h].name} (a copy, not a new "
                                    "photograph); not bound"))
            continue
        originals[h] = f
    files = list(originals.values())
    files.sort(key=(lambda f: (f.time, natural_key(f.name))) if by == "time" else (lambda f: natural_key(f.name)))
    return CameraListing(files=tuple(files), ignored=tuple(ignored))
