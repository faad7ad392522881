"""The full-size originals of the photo crops, for ``bench_photos.py --extra DIR``.

Run (one command; seconds)::

    python benchmarks/fetch_photos.py DIR --repo CLONE [--repo CLONE ...]
    python benchmarks/fetch_photos.py DIR --from FOLDER    # files downloaded by hand
    python benchmarks/fetch_photos.py DIR --download       # from GitHub (network)
    python benchmarks/bench_photos.py --extra DIR --repeats 1 --no-write

``tests/data/photos`` holds small crops (400x300 and less, 15-315 dots): too few
triples to rank the methods (their paired intervals hold 0). The originals have
300-4400 dots each; they are not committed (8 MB, and the licences ask for their
notices), so this script writes them into DIR, byte for byte as they are in their
repositories at the commits of ``tests/data/photos/README.md``:

============================== ============================ ==================================
written as                     repository                   path at the commit
============================== ============================ ==================================
discorpy_dot_pattern_02_full   DiamondLightSource/discorpy   data/dot_pattern_02.jpg
discorpy_dot_pattern_05_full   DiamondLightSource/discorpy   data/dot_pattern_05.jpg
discorpy_dot_pattern_06_full   DiamondLightSource/discorpy   data/dot_pattern_06.jpg
ucl_circles_right3_full        SciKit-Surgery/               tests/data/calib-ucl-circles/
                               scikit-surgeryimage           13_22_20/calib.right.images.3.png
ucl_circles_right0_full        (the same)                    .../calib.right.images.0.png
discorpy_dot_pattern_01_full   DiamondLightSource/discorpy   data/dot_pattern_01.jpg
discorpy_gopro8_dot_pattern    DiamondLightSource/discorpy   data/fisheye/GoPro8_dot_pattern.jpg
============================== ============================ ==================================

The last two are sets of another kind, with no crop committed: a dense grid of 6600
dots whose light falls to a third towards a vignetted border (``dot_pattern_01``), and
a colour photograph by a different camera (a GoPro HERO8's fisheye lens, 4000x3000
JPEG): uneven light, strong distortion, dots foreshortened to ellipses near the
border, heavy JPEG compression.

Where the bytes come from, first found first:

- ``--repo DIR``: a clone or a bare mirror (such as the search library's
  ``fetch github:DiamondLightSource/discorpy`` snapshot, ``.../repo``) of a repository holding the commit (the
  file is read with ``git show COMMIT:PATH``; which repository is which is told by
  the commit it holds); repeat for the second repository;
- ``--from FOLDER``: files downloaded by hand, each under its own name in the
  repository (``dot_pattern_02.jpg``, ``calib.right.images.3.png``);
- ``--download``: ``https://raw.githubusercontent.com/OWNER/NAME/COMMIT/PATH``.

Every file is checked against the git blob id of the repository's file (its SHA-1
as git computes it), so a file from anywhere is the original or is refused. Each is
written atomically; a file already in DIR with the right content is left alone. The
exit code is 1 when any original could not be had (each is reported with the reason).
"""

from __future__ import annotations

import argparse
import hashlib
import subprocess
import sys
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from vision_torsion.fileio import atomic_write_bytes

DISCORPY = ("DiamondLightSource/discorpy", "ffaa5d273142dabdb7a98fbbc1854a404577f3d1")
UCL = ("SciKit-Surgery/scikit-surgeryimage", "77f8a34992dcb48ebdd133be32e0ee9c142efa71")
UCL_FRAMES = "tests/data/calib-ucl-circles/13_22_20/calib.right.images"


@dataclass(frozen=True)
class Crop:
    """Where a committed crop of ``tests/data/photos`` lies in its original: its file
    name, its top-left pixel (row, column) and its size (rows, columns), as in the
    crop table of ``tests/data/photos/README.md``."""

    name: str
    top: int
    left: int
    rows: int
    cols: int


@dataclass(frozen=True)
class Original:
    """One original: the name it is written under, where it is, its git blob id, and
    the committed crop taken from it (None: none is)."""

    name: str
    repo: str
    commit: str
    path: str
    blob: str
    crop: Crop | None = None


ORIGINALS = (
    Original("discorpy_dot_pattern_02_full.jpg", *DISCORPY, "data/dot_pattern_02.jpg",
             "45c07258e211f2391797b54c13588c03e583f3f1", Crop("discorpy_dot_pattern_02.png", 930, 1080, 300, 400)),
    Original("discorpy_dot_pattern_05_full.jpg", *DISCORPY, "data/dot_pattern_05.jpg",
             "d9a0e1edbb8a5117955528e341055fe92f5d6ed6", Crop("discorpy_dot_pattern_05.png", 280, 480, 240, 320)),
    Original("discorpy_dot_pattern_06_full.jpg", *DISCORPY, "data/dot_pattern_06.jpg",
             "74e900c4a0f4af9fccd96f1bc2e5c8337d8559f3", Crop("discorpy_dot_pattern_06.png", 1082, 1440, 300, 400)),
    Original("ucl_circles_right3_full.png", *UCL, f"{UCL_FRAMES}.3.png", "7bc736facf724fa8e54f8a043b850b9033d5bfa7",
             Crop("ucl_circles_right3.png", 390, 760, 300, 400)),
    Original("ucl_circles_right0_full.png", *UCL, f"{UCL_FRAMES}.0.png", "96857564424a0d8a641a7b15803e98199061c374"),
    Original("discorpy_dot_pattern_01_full.jpg", *DISCORPY, "data/dot_pattern_01.jpg",
             "0170241b5aec583f8c90f69f980cd39020439048"),
    Original("discorpy_gopro8_dot_pattern.jpg", *DISCORPY, "data/fisheye/GoPro8_dot_pattern.jpg",
             "5bf1ee3fd2c36380475d217b4657c7159297071d"),
)


def blob_id(data: bytes) -> str:
    """The git blob id (SHA-1 of ``blob <size>\\0`` and the bytes) of `data`."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def _from_repo(original: Original, repo: Path) -> bytes | None:
    """The file at the commit in the git repository `repo` (a clone or a bare mirror),
    or None when that repository does not hold the commit."""
    done = subprocess.run(["git", "-C", str(repo), "show", f"{original.commit}:{original.path}"],
                          capture_output=True, check=False)
    return done.stdout if done.returncode == 0 else None


def _from_folder(original: Original, folder: Path) -> bytes | None:
    path = folder / Path(original.path).name
    return path.read_bytes() if path.is_file() else None


def _download(original: Original) -> bytes:
    url = f"https://raw.githubusercontent.com/{original.repo}/{original.commit}/{original.path}"
    with urllib.request.urlopen(url, timeout=60) as response:  # noqa: S310 (a fixed https URL)
        return response.read()


def fetch(out: Path, *, repos=(), folder: Path | None = None, download: bool = False) -> dict[str, str]:
    """Write every original into the folder `out` (made if missing), from the first
    source that has it (`repos`, then `folder`, then GitHub if `download`), each
    checked against its git blob id. Returns per written name ``"ok"`` or the reason
    it could not be had."""
    out.mkdir(parents=True, exist_ok=True)
    result = {}
    for original in ORIGINALS:
        target = out / original.name
        if target.is_file() and blob_id(target.read_bytes()) == original.blob:
            result[original.name] = "ok"
            continue
        tried = []
        sources = [(f"--repo {r}", lambda o, r=r: _from_repo(o, Path(r))) for r in repos]
        if folder is not None:
            sources.append((f"--from {folder}", lambda o: _from_folder(o, folder)))
        if download:
            sources.append(("--download", _download))
        for label, source in sources:
            try:
                data = source(original)
            except OSError as exc:  # a failed download, an unreadable file
                tried.append(f"{label}: {exc}")
                continue
            if data is None:
                continue
            if blob_id(data) != original.blob:
                tried.append(f"{label}: not the original (git blob {blob_id(data)[:12]}, "
                             f"expected {original.blob[:12]})")
                continue
            atomic_write_bytes(target, data)
            result[original.name] = "ok"
            break
        else:
            where = "; ".join(tried) or "in none of the sources given"
            result[original.name] = (f"not found: {original.repo} {original.commit[:12]} {original.path} "
                                     f"({where})")
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path, help="folder to write the originals into")
    ap.add_argument("--repo", action="append", default=[], metavar="DIR",
                    help="a clone or bare mirror of discorpy or scikit-surgeryimage (repeatable)")
    ap.add_argument("--from", dest="folder", type=Path, metavar="FOLDER",
                    help="a folder of files downloaded by hand, under their names in the repositories")
    ap.add_argument("--download", action="store_true", help="fetch what is still missing from GitHub")
    args = ap.parse_args(argv)
    result = fetch(args.out, repos=args.repo, folder=args.folder, download=args.download)
    for name, status in result.items():
        print(f"{name}: {status}")
    missing = sum(status != "ok" for status in result.values())
    if missing:
        print(f"{missing} of {len(result)} originals missing", file=sys.stderr)
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
