"""Reading and validating images: the one entry point for every image the toolkit reads.

Supported: PNG, TIFF, BMP and JPEG files with 8-bit, 12-bit (stored in 16-bit
containers, low-bit aligned, or high-bit aligned as a PNG ``sBIT`` chunk of 12 says)
or 16-bit samples. Colour images are converted to grey (ITU-R BT.601 weights, as
OpenCV does) with a logged notice. Corrupt, truncated, empty or non-image files raise
:class:`~vision_torsion.errors.ImageReadError` naming the file and the reason;
nothing is ever returned half-read.

What is checked, and why
------------------------
- The file's size and signature before it is read whole
  (:func:`read_image_bytes`): a file over :data:`MAX_IMAGE_FILE_BYTES`, or one
  that is no image, is refused after reading 16 bytes.
- The size the header states, before decoding, for every format (PNG's IHDR,
  TIFF's first directory, BMP's and JPEG's frame headers): an image smaller than
  :data:`MIN_SIDE_PX` on a side or larger than :data:`MAX_IMAGE_PIXELS` pixels is
  refused with its size (a PNG header claiming 50000x50000 would otherwise make
  OpenCV fail an assertion, a 1 MB deflate TIFF of 32000x32000 px decode 2 GB);
  a header that states no size is refused as corrupt.
- Fewer than 8 bits per grey sample (a 1-bit black-and-white PNG or TIFF) is
  refused: the markers' edges are fitted to grey levels.
- JPEGs are decoded by libjpeg-turbo through ``simplejpeg`` in strict mode: the
  decoder's warnings ("Corrupt JPEG data: 77 extraneous bytes before marker 0xd9",
  "premature end of data segment") make the image fail with the decoder's words.
  OpenCV prints the same warnings to stderr, unattributed, and returns an image
  whose damaged blocks are filled in: a corrupt JPEG measured that way gave an
  angle 0.42 degrees off with status ``ok``. The pixels are the same as OpenCV's.
- Bytes after a PNG's IEND chunk or a JPEG's end-of-image marker (some cameras and
  transfer tools append them) are ignored, with a logged note.
- Any other decoder failure (an OpenCV assertion included) is the image's failure,
  with the decoder's first line.

Grey PNGs whose rows are filtered as OpenCV writes them are decoded by
:mod:`vision_torsion.pngrows` (the same samples, in less than half the time); every other file,
and any such PNG it has a doubt about, by OpenCV.

Arrays handed straight to the measuring functions go through :func:`as_grey_array`,
the single validator for in-memory images.
"""

from __future__ import annotations

import logging
import os
import stat
import struct
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from .errors import ImageReadError
from .pngrows import decode_grey_png
from .textfiles import nonblocking_opener

__all__ = ["GreyImage", "load_image", "decode_image", "as_grey_array", "grey_array_and_blocks", "IMAGE_SUFFIXES",
           "write_image", "MAX_IMAGE_PIXELS", "MIN_SIDE_PX", "image_size", "read_image_bytes", "MAX_IMAGE_FILE_BYTES"]

logger = logging.getLogger(__name__)

#: File name endings the toolkit treats as images (lower case).
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg")

#: Largest image accepted, in pixels (2**28, 268 Mpx: 1 GB as float32). Larger
#: headers are refused before decoding.
MAX_IMAGE_PIXELS = 1 << 28
#: Largest image file read (bytes, 2 GiB): an uncompressed 16-bit colour image of
#: :data:`MAX_IMAGE_PIXELS` is 1.6 GB. Checked before the file is read.
MAX_IMAGE_FILE_BYTES = 1 << 31
#: Smallest side accepted, in pixels (the marker finder needs at least this).
MIN_SIDE_PX = 8

_PNG_IEND = b"IEND\xaeB`\x82"  # the IEND chunk's type and (fixed) CRC

_MAGIC = {
    "png": (b"\x89PNG\r\n\x1a\n",),
    "jpeg": (b"\xff\xd8\xff",),
    "tiff": (b"II*\x00", b"MM\x00*"),
    "bmp": (b"BM",),
}


@dataclass(frozen=True)
class GreyImage:
    """A grey-level image as read from disk.

    Attributes
    ----------
    data : numpy.ndarray
        2-D float32 array of grey levels in digital numbers (DN) of the file (or the
        file's own uint8/uint16 samples, when read with ``keep_integers=True``),
        indexed ``data[y, x]``; pixel centres are at integer coordinates, origin at
        the centre of the top-left pixel.
    path : str
        The file it came from.
    bit_depth : int
        8, 12 or 16: the significant bits per sample.
    was_colour : bool
        True when the file held colour and was converted to grey.
    jpeg_block_px : int
        The side (px) of the blocks a JPEG's grey levels were compressed in, whose
        errors are correlated within a block: 8 (the luma's blocks; also when
        libjpeg-turbo gives a colour file's luma as its grey), 16 when OpenCV
        converted a colour JPEG to grey (its chroma is subsampled in 16x16 blocks
        at most). 0 for lossless files. The marker fits take their covariance
        from these blocks (:mod:`vision_torsion.pixelfit`).
    """

    data: np.ndarray
    path: str
    bit_depth: int
    was_colour: bool = False
    jpeg_block_px: int = 0

    @property
    def full_scale(self) -> float:
        """Largest representable grey level, ``2**bit_depth - 1`` (DN)."""
        return float(2**self.bit_depth - 1)


def _kind_from_magic(head: bytes) -> str | None:
    for kind, magics in _MAGIC.items():
        if any(head.startswith(m) for m in magics):
            return kind
    return None


def _check_complete(raw: bytes, kind: str, name: str = "") -> str | None:
    """Return why the file looks truncated, or None if its structure is complete.

    Bytes after a PNG's IEND chunk or a JPEG's end-of-image marker are accepted,
    with a logged note.
    """
    if kind == "png":
        # A complete PNG ends with the IEND chunk (length 0, type IEND, CRC).
        if _PNG_IEND not in raw[-12:]:
            end = raw.rfind(_PNG_IEND)
            if end < 0:
                return "truncated PNG (no IEND chunk at the end)"
            logger.warning("%s: %d bytes after the end of the PNG (its IEND chunk) ignored",
                           name, len(raw) - end - len(_PNG_IEND))
    elif kind == "jpeg":
        if b"\xff\xd9" not in raw[-64:]:
            # entropy-coded data never holds FF D9 (an FF there is followed by 00
            # or a restart marker); an embedded thumbnail ends well before the scan
            end = raw.rfind(b"\xff\xd9")
            if end < len(raw) // 2:
                return "truncated JPEG (no end-of-image marker)"
            logger.warning("%s: %d bytes after the end of the JPEG (its end-of-image marker) "
                           "ignored", name, len(raw) - end - 2)
    elif kind == "bmp":
        if len(raw) >= 6:
            declared = struct.unpack("<I", raw[2:6])[0]
            if declared and len(raw) < declared:
                return f"truncated BMP ({len(raw)} of {declared} bytes)"
    return None


def _png_chunks(raw: bytes):
    """(type, data) of a PNG's chunks before its first IDAT."""
    pos = 8
    while pos + 8 <= len(raw):
        length, kind = struct.unpack(">I4s", raw[pos:pos + 8])
        if kind == b"IDAT" or length > len(raw):
            return
        yield kind, raw[pos + 8:pos + 8 + length]
        pos += 12 + length


def _png_significant_bits(raw: bytes) -> int | None:
    """Significant bits from a PNG sBIT chunk (before the image data), if present."""
    for kind, data in _png_chunks(raw):
        if kind == b"sBIT" and data:
            return int(data[0])
    return None


def _tiff_tags(raw: bytes, tags) -> dict:
    """First value of each of `tags` in a TIFF's first image file directory (IFD0)."""
    order = "<" if raw[:2] == b"II" else ">"
    (offset,) = struct.unpack(order + "I", raw[4:8])
    (count,) = struct.unpack(order + "H", raw[offset:offset + 2])
    found = {}
    for i in range(count):
        entry = raw[offset + 2 + 12 * i:offset + 14 + 12 * i]
        tag, kind, n = struct.unpack(order + "HHI", entry[:8])
        if tag not in tags or kind not in (3, 4):  # SHORT or LONG
            continue
        size = 2 if kind == 3 else 4
        if n * size <= 4:  # the value is in the entry
            at = entry[8:8 + size]
        else:  # the entry holds the offset of the values
            (where,) = struct.unpack(order + "I", entry[8:12])
            at = raw[where:where + size]
        found[tag] = struct.unpack(order + ("H" if kind == 3 else "I"), at)[0]
    return found


def image_size(raw: bytes, kind: str) -> tuple[int, int] | None:
    """(width, height) in pixels as the file's header states it, or None if the
    header does not say (a corrupt header, or a JPEG whose scan comes before its
    frame header)."""
    try:
        if kind == "png" and raw[12:16] == b"IHDR":
            return struct.unpack(">II", raw[16:24])
        if kind == "bmp" and len(raw) >= 26:
            if struct.unpack("<I", raw[14:18])[0] == 12:  # OS/2 BITMAPCOREHEADER: 16-bit sides
                return struct.unpack("<HH", raw[18:22])
            w, h = struct.unpack("<ii", raw[18:26])
            return abs(w), abs(h)
        if kind == "tiff":
            tags = _tiff_tags(raw, (256, 257))  # ImageWidth, ImageLength
            return (tags[256], tags[257]) if len(tags) == 2 else None
        if kind == "jpeg":
            pos = 2
            while pos + 4 <= len(raw):
                if raw[pos] != 0xFF:
                    return None
                marker = raw[pos + 1]
                if marker == 0xFF:  # fill byte
                    pos += 1
                    continue
                length = struct.unpack(">H", raw[pos + 2:pos + 4])[0]
                if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                    h, w = struct.unpack(">HH", raw[pos + 5:pos + 9])
                    return w, h
                if marker == 0xDA:  # start of scan before any frame header
                    return None
                pos += 2 + length
    except (struct.error, IndexError, KeyError):
        return None
    return None


def _sample_bits(raw: bytes, kind: str) -> int | None:
    """Bits per grey sample the header states, for the kinds that can hold fewer than
    8 (PNG greyscale, TIFF); None when it does not say or the file holds palette
    indices (expanded to colour by the decoder)."""
    try:
        if kind == "png" and raw[12:16] == b"IHDR" and raw[25] == 0:  # colour type 0: grey
            return raw[24]
        if kind == "tiff":
            return _tiff_tags(raw, (258,)).get(258, 1)  # BitsPerSample, 1 when absent (TIFF 6.0)
    except (struct.error, IndexError):
        return None
    return None


def _check_size(size, name: str, kind: str = "") -> None:
    if size is None:
        raise ImageReadError(f"{name}: corrupt {kind.upper()} header (it does not state the image size)")
    w, h = size
    if w * h > MAX_IMAGE_PIXELS:
        raise ImageReadError(f"{name}: image larger than the limit ({w}x{h} px = {w * h / 1e6:.0f} Mpx; "
                             f"at most {MAX_IMAGE_PIXELS / 1e6:.0f} Mpx)")
    if min(w, h) < MIN_SIDE_PX:
        raise ImageReadError(f"{name}: image too small ({w}x{h} px; at least "
                             f"{MIN_SIDE_PX}x{MIN_SIDE_PX} px needed)")


def _decode_jpeg(raw: bytes, name: str):
    """The grey levels of a JPEG by libjpeg-turbo in strict mode (see the module
    docstring), or None when simplejpeg cannot decode this kind of JPEG (CMYK,
    12-bit, arithmetic coding), for OpenCV to try.

    Returns
    -------
    (numpy.ndarray, bool) or None
        The uint8 grey levels and whether the file held colour.
    """
    import simplejpeg

    try:
        colour = simplejpeg.decode_jpeg_header(raw)[2] not in ("Gray",)
        return simplejpeg.decode_jpeg(raw, colorspace="GRAY", strict=True)[:, :, 0], colour
    except ValueError as strict_error:
        try:  # a recoverable error (a warning) decodes without strict: corrupt data
            simplejpeg.decode_jpeg(raw, colorspace="GRAY", strict=False)
        except ValueError:
            return None
        raise ImageReadError(f"{name}: corrupt JPEG data (the decoder said: "
                             f"{_first_line(strict_error)})") from None


def _first_line(exc) -> str:
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def load_image(path, *, bit_depth: int | None = None, keep_integers: bool = False) -> GreyImage:
    """Read an image file as grey levels.

    Parameters
    ----------
    path : str or os.PathLike
        PNG, TIFF, BMP or JPEG file.
    bit_depth : {None, 8, 12, 16}, optional
        Significant bits of a 16-bit file. None infers it: 8 for 8-bit files; for
        16-bit files the PNG ``sBIT`` chunk if present, else 12 when no sample exceeds
        4095, else 16.
    keep_integers : bool
        Keep the file's uint8/uint16 samples instead of converting them to float32
        (the measuring code converts only the pixels it uses).

    Returns
    -------
    GreyImage
        The grey levels (DN, float32 unless `keep_integers`) with the file's path
        and bit depth.

    Raises
    ------
    ImageReadError
        The file is missing, empty, larger than :data:`MAX_IMAGE_FILE_BYTES`, not an
        image, truncated, corrupt (a JPEG the decoder warns about included, a header
        that states no size), smaller than :data:`MIN_SIDE_PX` or larger than
        :data:`MAX_IMAGE_PIXELS`, of fewer than 8 bits or an unsupported sample
        type, or has samples above the stated bit depth. The message names the file
        and the reason.

    Examples
    --------
    >>> import tempfile, os, numpy as np, cv2
    >>> d = tempfile.mkdtemp()
    >>> p = os.path.join(d, "a.png")
    >>> _ = cv2.imwrite(p, np.full((8, 10), 7, np.uint8))
    >>> img = load_image(p)
    >>> img.data.shape, img.bit_depth, float(img.data[0, 0])
    ((8, 10), 8, 7.0)
    """
    name = str(Path(path))
    return decode_image(read_image_bytes(path), name=name, bit_depth=bit_depth, keep_integers=keep_integers)


def read_image_bytes(path, *, signature: bool = True) -> bytes:
    """The bytes of an image file, its size and kind checked before it is read whole.

    The file's size (at most :data:`MAX_IMAGE_FILE_BYTES`) and, with `signature`,
    its first bytes (a PNG, TIFF, BMP or JPEG signature) are checked first, so a
    huge file, or one that is no image, is refused without reading it; the header's
    image size is checked by :func:`decode_image` before decoding. A caller that
    records a failure by the file's content (a cache keyed by its hash) passes
    ``signature=False`` and lets :func:`decode_image` refuse a non-image.

    Raises
    ------
    ImageReadError
        Naming the file: no such file (a broken link included), a folder, a named
        pipe or a device, a link that loops or cannot be read (permissions, I/O
        error), empty, larger than
        :data:`MAX_IMAGE_FILE_BYTES`, or not an image (unrecognised header).
    """
    p = Path(path)
    name = str(p)
    try:
        # unbuffered: the file is read straight into the bytes returned (a buffered
        # reader's read of the whole file cost the demo's 0.6 MB PNGs ~0.08 ms more);
        # O_NONBLOCK: opening a named pipe must not wait for a writer
        with open(p, "rb", buffering=0, opener=nonblocking_opener) as fh:
            st = os.fstat(fh.fileno())
            if stat.S_ISDIR(st.st_mode):
                raise IsADirectoryError
            if not stat.S_ISREG(st.st_mode):
                raise ImageReadError(f"{name}: not a regular file (a named pipe or a device), not an image file")
            size = st.st_size
            if size > MAX_IMAGE_FILE_BYTES:
                raise ImageReadError(f"{name}: {size} bytes, larger than an image file may be "
                                     f"({MAX_IMAGE_FILE_BYTES} bytes)", reason="too_large")
            if signature:
                head = fh.read(16)
                fh.seek(0)
                if head and _kind_from_magic(head) is None:
                    raise ImageReadError(f"{name}: not a PNG, TIFF, BMP or JPEG image (unrecognised file header)")
            # the file in one read, as its size says (one more byte tells a file still
            # growing); asking read() for the largest allowed size would allocate that
            # much for every image
            return _read_up_to(fh, max(size, 16) + 1, size)
    except FileNotFoundError:
        raise ImageReadError(f"{name}: no such file", reason="not_found") from None
    except IsADirectoryError:
        raise ImageReadError(f"{name}: is a folder, not an image file") from None
    except ImageReadError:
        raise
    except OSError as exc:
        raise ImageReadError(f"{name}: cannot be read ({exc.strerror or exc})") from exc


def _read_up_to(fh, n: int, size: int) -> bytes:
    """Up to `n` bytes of the unbuffered file `fh` whose size was `size` bytes: one
    read for a local file, more where a read returns less than there is (a network
    file system), until `n` bytes or the file's end."""
    data = fh.read(n)
    if len(data) >= size:
        return data
    parts, got = [data], len(data)
    while got < n and (more := fh.read(n - got)):
        parts.append(more)
        got += len(more)
    return b"".join(parts)


def decode_image(raw: bytes, *, name: str, bit_depth: int | None = None, keep_integers: bool = False) -> GreyImage:
    """Decode and validate the bytes of an image file, as :func:`load_image` does.

    For callers that already hold the file's bytes (a session worker hashes them
    for its cache before measuring): the file is read once.

    Parameters
    ----------
    raw : bytes
        The file's contents.
    name : str
        The file's path, for :attr:`GreyImage.path` and error messages.
    bit_depth, keep_integers
        As for :func:`load_image`.

    Returns
    -------
    GreyImage

    Raises
    ------
    ImageReadError
        As for :func:`load_image`, for everything but reading the file.
    """
    if bit_depth not in (None, 8, 12, 16):
        raise ImageReadError(f"{name}: bit_depth must be 8, 12 or 16, got {bit_depth!r}")
    if not raw:
        raise ImageReadError(f"{name}: empty file (0 bytes)")
    kind = _kind_from_magic(raw[:8])
    if kind is None:
        raise ImageReadError(
            f"{name}: not a PNG, TIFF, BMP or JPEG image (unrecognised file header)"
        )
    why = _check_complete(raw, kind, name)
    if why:
        raise ImageReadError(f"{name}: {why}")
    _check_size(image_size(raw, kind), name, kind)
    bits = _sample_bits(raw, kind)
    if bits is not None and bits < 8:
        raise ImageReadError(f"{name}: {bits}-bit {kind.upper()} (black and white or few grey levels); the "
                             "markers' edges are fitted to grey levels: save 8-, 12- or 16-bit grey",
                             reason="unsupported_image")
    if kind == "jpeg":
        decoded = _decode_jpeg(raw, name)
        if decoded is not None:
            arr, colour = decoded
            if colour:
                logger.info("%s: colour image converted to grey (BT.601 weights)", name)
            image = _to_grey(arr, name=name, kind=kind, raw=raw, bit_depth=bit_depth,
                             keep_integers=keep_integers)
            return GreyImage(image.data, image.path, image.bit_depth, was_colour=colour, jpeg_block_px=8)
    arr = decode_grey_png(raw) if kind == "png" else None  # the same samples, sooner (.pngrows)
    if arr is None:
        arr = _decode_opencv(raw, name, kind)
    image = _to_grey(arr, name=name, kind=kind, raw=raw, bit_depth=bit_depth, keep_integers=keep_integers)
    if kind == "jpeg":  # a kind simplejpeg does not decode (12-bit, CMYK, arithmetic coding)
        return replace(image, jpeg_block_px=16 if image.was_colour else 8)
    return image


def _decode_opencv(raw: bytes, name: str, kind: str) -> np.ndarray:
    """The samples of a file as OpenCV decodes it (``IMREAD_UNCHANGED``); its
    failure is the image's, with the decoder's first line."""
    try:
        arr = cv2.imdecode(np.frombuffer(raw, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ImageReadError(f"{name}: corrupt {kind.upper()} data (the decoder failed: "
                             f"{_first_line(exc).split(') ', 1)[-1]})") from None
    if arr is None or arr.size == 0:
        raise ImageReadError(f"{name}: corrupt {kind.upper()} data (the decoder failed)")
    return arr


def _to_grey(arr: np.ndarray, *, name: str, kind: str, raw: bytes, bit_depth, keep_integers=False) -> GreyImage:
    was_colour = False
    if arr.ndim == 3:
        channels = arr.shape[2]
        if channels == 1:
            arr = arr[:, :, 0]
        elif channels == 2:  # grey + alpha
            arr = arr[:, :, 0]
        elif channels in (3, 4):
            code = cv2.COLOR_BGR2GRAY if channels == 3 else cv2.COLOR_BGRA2GRAY
            if arr.dtype not in (np.uint8, np.uint16, np.float32):
                arr = arr.astype(np.float32)
            arr = cv2.cvtColor(arr, code)
            was_colour = True
            logger.info("%s: colour image converted to grey (BT.601 weights)", name)
        else:
            raise ImageReadError(f"{name}: unsupported number of channels ({channels})")
    elif arr.ndim != 2:
        raise ImageReadError(f"{name}: unsupported image shape {arr.shape}")
    _check_size((arr.shape[1], arr.shape[0]), name)
    if arr.dtype == np.uint8:
        depth = 8
        if bit_depth not in (None, 8):
            raise ImageReadError(f"{name}: 8-bit file but bit_depth={bit_depth} was requested")
    elif arr.dtype == np.uint16:
        peak = int(arr.max())
        if bit_depth is not None:
            depth = bit_depth
        else:
            sbit = _png_significant_bits(raw) if kind == "png" else None
            if sbit is not None and 8 < sbit < 16 and peak > 2**sbit - 1:
                # high-bit aligned (PNG's own convention for sBIT: samples scaled
                # to 16 bits, as many machine-vision cameras write 12-bit data)
                shift = 16 - sbit
                arr = arr >> np.uint16(shift)
                peak >>= shift
                logger.info("%s: %d-bit samples aligned to the high bits (sBIT); shifted "
                            "right by %d", name, sbit, shift)
                depth = 12 if sbit <= 12 else 16
            elif sbit in (12, 16):
                depth = sbit
            else:
                depth = 12 if peak <= 4095 else 16
        if peak > 2**depth - 1:
            raise ImageReadError(
                f"{name}: sample value {peak} exceeds the {depth}-bit range (0..{2**depth - 1})"
            )
    else:
        raise ImageReadError(
            f"{name}: unsupported sample type {arr.dtype} (expected 8- or 16-bit integers)"
        )
    data = np.ascontiguousarray(arr) if keep_integers else np.ascontiguousarray(arr, dtype=np.float32)
    return GreyImage(data=data, path=name, bit_depth=depth, was_colour=was_colour)


def as_grey_array(image, *, name: str = "image", keep_integers: bool = False) -> np.ndarray:
    """Validate an image given as an array, a :class:`GreyImage` or a path.

    Parameters
    ----------
    image : array_like, GreyImage, str or os.PathLike
        A 2-D array of grey levels indexed ``[y, x]`` (or an RGB/RGBA colour array
        ``[y, x, channel]``, converted to grey as colour files are), an already
        loaded image, or a file to load with :func:`load_image`.
    name : str
        What to call the image in error messages.
    keep_integers : bool
        Return 8- and 16-bit integer arrays as they are (they cannot hold NaN), for
        callers that convert only the pixels they use.

    Returns
    -------
    numpy.ndarray
        2-D float32 array (or the integer array, with `keep_integers`). The caller's
        array is never modified (a copy is made when a conversion is needed, and
        callers must not write into the result).

    Raises
    ------
    ImageReadError
        Not two-dimensional, empty, smaller than 8x8, or containing NaN/inf.
    """
    if isinstance(image, GreyImage):
        return image.data
    if isinstance(image, (str, os.PathLike)):
        return load_image(image, keep_integers=keep_integers).data
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] in (3, 4) and min(arr.shape[:2]) >= 8 and arr.dtype.kind in "uif":
        # as a colour file is: converted to grey, with a logged notice. Arrays come in
        # RGB(A) order, as NumPy readers (imageio, PIL, scikit-image) give them.
        code = cv2.COLOR_RGB2GRAY if arr.shape[2] == 3 else cv2.COLOR_RGBA2GRAY
        if arr.dtype not in (np.uint8, np.uint16, np.float32):
            arr = arr.astype(np.float32)
        arr = cv2.cvtColor(np.ascontiguousarray(arr), code)
        logger.info("%s: colour array converted to grey (BT.601 weights, RGB order)", name)
    if arr.ndim != 2:
        raise ImageReadError(f"{name}: expected a 2-D grey image, got shape {arr.shape}")
    if min(arr.shape) < 8:
        raise ImageReadError(f"{name}: image too small ({arr.shape[1]}x{arr.shape[0]} px)")
    if arr.dtype.kind not in "uif":
        raise ImageReadError(f"{name}: unsupported array type {arr.dtype}")
    if keep_integers and arr.dtype in (np.uint8, np.uint16):
        return arr
    out = np.asarray(arr, dtype=np.float32)
    if arr.dtype.kind == "f" and not np.all(np.isfinite(out)):
        raise ImageReadError(f"{name}: contains NaN or infinite values")
    return out


def grey_array_and_blocks(image, *, name: str = "image", keep_integers: bool = False) -> tuple[np.ndarray, int | None]:
    """:func:`as_grey_array` of `image` and the side (px) of the blocks its grey
    levels were compressed in (:attr:`GreyImage.jpeg_block_px`; None for a lossless
    file or an array), which the marker fits' covariance takes: a path is loaded as a
    :class:`GreyImage` to learn it."""
    if isinstance(image, (str, os.PathLike)):
        image = load_image(image, keep_integers=keep_integers)
    return as_grey_array(image, name=name, keep_integers=keep_integers), (getattr(image, "jpeg_block_px", 0) or None)


def write_image(path, data: np.ndarray, *, bit_depth: int = 8, jpeg_quality: int | None = None) -> None:
    """Write grey levels to an image file atomically (temporary file, then rename).

    Parameters
    ----------
    path : str or os.PathLike
        Destination; the suffix chooses the format (.png, .tif, .bmp, .jpg).
    data : numpy.ndarray
        2-D grey levels in DN of `bit_depth`; rounded and clipped to the range.
    bit_depth : {8, 12, 16}
        8 writes uint8; 12 and 16 write uint16 (12-bit PNGs carry an sBIT chunk
        only implicitly: readers infer 12 bits from the sample range).
    jpeg_quality : int, optional
        JPEG quality 1-100 for .jpg files.
    """
    p = Path(path)
    top = 2**bit_depth - 1
    dtype = np.uint8 if bit_depth == 8 else np.uint16
    arr = np.clip(np.rint(data), 0, top).astype(dtype)
    params = []
    if p.suffix.lower() in (".jpg", ".jpeg") and jpeg_quality is not None:
        params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
    ok, enc = cv2.imencode(p.suffix.lower(), arr, params)
    if not ok:
        raise ImageReadError(f"{p}: OpenCV could not encode a {p.suffix} image")
    from .fileio import atomic_write_bytes

    atomic_write_bytes(p, enc.tobytes())
