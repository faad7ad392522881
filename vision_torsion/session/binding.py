"""``binding.json``: which camera file is the photograph of which manifest row.

A camera writes ``IMG_0001.JPG, IMG_0002.JPG, ...``; the manifest names every image
it expects (``images/o000_c1_01_positive_unloading_s00.png``). Rather than
renaming or copying the camera's files (the camera folder is an input and is never
written), ``vision-torsion bind`` (:mod:`.bind`) and ``vision-torsion watch``
(:mod:`.watch`) write this small file into the session folder, and
:func:`~vision_torsion.session.manifest.load_manifest` reads the rows' images
through it. Its layout (JSON, written atomically)::

    {"format": 1,
     "camera_dir": "/absolute/path/of/the/camera/folder",
     "by": "time",                       # how the files were ordered
     "images": {"images/o000_..._s00.png": "IMG_0002.JPG", ...},
     "skipped": ["IMG_0017.JPG"],        # camera files left out on purpose
     "missing": [31]}                    # manifest lines with no photograph

Only ``camera_dir`` and ``images`` change what is measured; a row not in
``images`` is looked for under its planned name in the session folder.

Images may live outside the session folder only in the folder the user named
(``camera_dir``); a file there that is a symbolic link leading out of it is refused,
as a link leading out of the session folder is.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from ..errors import SessionError
from ..fileio import atomic_write_text
from ..textfiles import decode_utf8, read_text_bytes
from ..validate import number_problem

__all__ = ["Binding", "load_binding", "write_binding", "BINDING_NAME"]

#: File name of the binding inside a session folder.
BINDING_NAME = "binding.json"
_FORMAT = 1


@dataclass(frozen=True)
class Binding:
    """Camera files bound to manifest rows.

    Attributes
    ----------
    camera_dir : pathlib.Path
        The camera's folder (absolute), named by the user.
    images : dict of str to str
        Manifest image path -> file name relative to `camera_dir`.
    by : str
        How the camera files were ordered: "time", "name" or "watch".
    skipped : tuple of str
        Camera files deliberately left unbound (extra shots).
    missing : tuple of int
        Manifest CSV lines with no photograph (missed shots).
    """

    camera_dir: Path
    images: dict = field(default_factory=dict)
    by: str = "time"
    skipped: tuple = ()
    missing: tuple = ()

    def source(self, image: str) -> Path | None:
        """Absolute path of the camera file bound to manifest image `image`, or None."""
        name = self.images.get(image)
        return None if name is None else self.camera_dir / name

    def check_camera_dir(self, binding_path) -> None:
        """Raise when photographs are bound but the camera folder is not there.

        A removed card, an unmounted share or a renamed folder must not turn every
        bound row into "not photographed yet": that would rewrite a table of
        measured rows as pending and exit as if nothing were wrong.

        Raises
        ------
        SessionError
            reason ``"camera_dir_missing"``: `camera_dir` is not a folder while
            `images` binds rows to files in it.
        """
        if self.images and not self.camera_dir.is_dir():
            raise SessionError(
                f"{self.camera_dir}: the camera folder named in {binding_path} is not there "
                f"(a card removed, a share not mounted, a folder renamed?); {len(self.images)} "
                "row(s) are bound to files in it. Put it back, or run `vision-torsion bind` "
                "with its new place", reason="camera_dir_missing")

    def to_dict(self) -> dict:
        return {"format": _FORMAT, "camera_dir": str(self.camera_dir), "by": self.by,
                "images": dict(self.images), "skipped": list(self.skipped),
                "missing": list(self.missing)}


#: How the files were bound: bind's two orders (:mod:`.camera`), or as they came (``watch``).
_ORDERS = ("time", "name", "watch")


def load_binding(session_dir) -> Binding | None:
    """The binding of a session folder, or None when it has none.

    Raises
    ------
    SessionError
        binding.json is not valid JSON or lacks ``camera_dir``/``images``, a bound
        name is absolute or leaves the camera folder ('..'), or ``by``, ``skipped``
        or ``missing`` has the wrong type (a hand edit); the message names the key.
    """
    path = Path(session_dir) / BINDING_NAME
    try:  # a named pipe under its name is refused, never waited on
        raw = read_text_bytes(path, what="binding.json", error=SessionError)
    except SessionError as exc:
        if exc.reason == "not_found":
            return None
        raise
    text = decode_utf8(raw, name=path, error=SessionError, what="binding.json")
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise SessionError(f"{path}: not valid JSON ({exc}); run `vision-torsion bind` "
                           "again to rewrite it") from exc
    if not isinstance(doc, dict) or not isinstance(doc.get("camera_dir"), str) \
            or not isinstance(doc.get("images"), dict):
        raise SessionError(f"{path}: expected a JSON object with 'camera_dir' (a folder) and "
                           "'images' (manifest image -> camera file)")
    for image, name in doc["images"].items():
        posix = PurePosixPath(str(name))
        if not isinstance(name, str) or posix.is_absolute() or ".." in posix.parts:
            raise SessionError(f"{path}: {image!r} is bound to {name!r}; expected a file name "
                               "inside the camera folder")
    by, skipped, missing = doc.get("by", "time"), doc.get("skipped", []), doc.get("missing", [])
    if by not in _ORDERS:
        raise SessionError(f"{path}: 'by' is {by!r}; expected one of {', '.join(map(repr, _ORDERS))}; run "
                           "`vision-torsion bind` again to rewrite it")
    if not isinstance(skipped, list) or not all(isinstance(x, str) for x in skipped):
        raise SessionError(f"{path}: 'skipped' is {skipped!r}; expected a list of camera file names; run "
                           "`vision-torsion bind` again to rewrite it")
    if not isinstance(missing, list) or any(number_problem(x, low=2, whole=True) for x in missing):
        raise SessionError(f"{path}: 'missing' is {missing!r}; expected a list of manifest line numbers "
                           "(whole numbers >= 2); run `vision-torsion bind` again to rewrite it")
    return Binding(camera_dir=Path(doc["camera_dir"]), images=dict(doc["images"]),
                   by=by, skipped=tuple(skipped), missing=tuple(int(x) for x in missing))


def write_binding(session_dir, binding: Binding, *, durable: bool = True) -> Path:
    """Write `binding` to ``SESSION_DIR/binding.json`` atomically; return its path.

    `durable` flushes it to the disk first (see :func:`~vision_torsion.fileio.atomic_write_bytes`);
    ``watch``, which rewrites it at every photograph and can rebuild it, does not."""
    text = json.dumps(binding.to_dict(), indent=1, ensure_ascii=False)
    return atomic_write_text(Path(session_dir) / BINDING_NAME, text + "\n", durable=durable)
