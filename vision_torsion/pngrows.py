"""Decoding the grey PNGs whose rows need no prediction from their neighbours' left
and upper-left samples: inflated by ISA-L (``isal``, where it is installed; else
zlib), their row filters undone by array operations.

A PNG's rows are each stored with one of five filters. OpenCV writes every row
"Sub" (each byte stored as its difference from the byte one sample to the left), and
so does every program that saves its images through OpenCV; "None" and "Up" are the
other two that depend on no sample diagonal to the one being decoded. For 8- and 16-bit grey PNGs
of those three filters, not interlaced, :func:`decode_grey_png` gives the same
samples as OpenCV's decoder (libpng) for less work: inflating is most of a PNG's
decoding, and ISA-L inflates ~2.7x faster than the zlib OpenCV and Python are built
with (``benchmarks/bench_commands.py`` times the whole command).

Any other PNG, and any doubt about one (a chunk's CRC that does not match, a chunk
out of order, a critical chunk this decoder does not know, image data that does not
end where its rows do), gives None: the caller then decodes the file with OpenCV,
whose verdict and messages stand. So does a file whose structure would cost this
decoder's Python loops much more than its pixels: over :data:`MAX_CHUNKS` chunks, or
over :data:`MAX_UP_RUNS` runs of Up rows. A Sub row's bytes are running sums modulo 256,
which :func:`cv2.integral` computes; only the low byte of its 32-bit sums is used,
and the rows are taken in bands small enough that no sum exceeds 2**31 - 1.
"""

from __future__ import annotations

import struct
import sys

import cv2
import numpy as np

try:  # the same bytes as zlib gives, sooner; not built for every platform
    from isal import isal_zlib as _zlib
except ImportError:  # pragma: no cover - isal is a dependency where it has wheels
    import zlib as _zlib

__all__ = ["decode_grey_png", "MAX_CHUNKS", "MAX_UP_RUNS"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_NONE, _SUB, _UP = 0, 1, 2
#: Index of a little- or big-endian int32's lowest byte among its four.
_LOW_BYTE = 0 if sys.byteorder == "little" else 3
_INT32_MAX = 2**31 - 1
#: Most chunks a PNG may have for this decoder (OpenCV's 8 kB IDAT chunks: ~1000 for
#: a 20-Mpx grey image); more are left to OpenCV, which reads them in C.
MAX_CHUNKS = 1 << 16
#: Most runs of consecutive Up rows (each one array operation here); more are left
#: to OpenCV.
MAX_UP_RUNS = 64


def decode_grey_png(raw: bytes) -> np.ndarray | None:
    """The samples of an 8- or 16-bit grey, non-interlaced PNG whose rows are
    filtered None, Sub or Up; None for any other PNG or any doubt about this one.

    Parameters
    ----------
    raw : bytes
        The whole file.

    Returns
    -------
    numpy.ndarray or None
        ``(height, width)`` uint8 or uint16 (native byte order) samples, as
        ``cv2.imdecode(..., cv2.IMREAD_UNCHANGED)`` gives them; None when the file
        is not such a PNG, or is damaged in any way this decoder checks (the
        caller decodes it with OpenCV then).
    """
    header = _header_and_data(raw)
    if header is None:
        return None
    (width, height, sample_bytes), data = header
    stride = width * sample_bytes
    expected = height * (stride + 1)
    inflater = _zlib.decompressobj()
    try:
        out = inflater.decompress(data, expected + 1)  # room for the stream's checksum
    except _zlib.error:
        return None
    if len(out) != expected or not inflater.eof or inflater.unconsumed_tail or inflater.unused_data:
        return None
    rows = np.frombuffer(out, np.uint8).reshape(height, stride + 1)
    filters = rows[:, 0]
    if int(filters.max()) > _UP:
        return None
    samples = _unfilter(rows[:, 1:], filters, sample_bytes)
    if samples is None:
        return None
    if sample_bytes == 1:
        return samples
    return samples.view(">u2").astype(np.uint16)


def _header_and_data(raw: bytes):
    """((width, height, bytes per sample), the IDAT chunks' data joined) of a PNG
    this module decodes, or None."""
    if not raw.startswith(_SIGNATURE):
        return None
    view = memoryview(raw)
    pos, header, parts, idat_done = 8, None, [], False
    for _ in range(MAX_CHUNKS):
        if pos + 12 > len(raw):
            return None
        length, kind = struct.unpack_from(">I4s", raw, pos)
        end = pos + 12 + length
        if end > len(raw):
            return None
        body = view[pos + 8:end - 4]
        if _zlib.crc32(view[pos + 4:end - 4]) != struct.unpack_from(">I", raw, end - 4)[0]:
            return None
        if header is None:  # IHDR must come first
            if kind != b"IHDR" or length != 13:
                return None
            width, height, depth, colour, method, filtering, interlace = struct.unpack(">IIBBBBB", body)
            if colour != 0 or depth not in (8, 16) or (method, filtering, interlace) != (0, 0, 0) \
                    or not width or not height:
                return None
            header = (width, height, depth // 8)
        elif kind == b"IDAT":
            if idat_done:
                return None
            parts.append(body)
        elif kind == b"IEND":
            return (header, b"".join(parts)) if parts else None
        elif kind[0] & 0x20 == 0:  # a critical chunk other than IHDR, IDAT, IEND
            return None
        else:  # an ancillary chunk (text, sBIT, pHYs, gamma...): the samples stay as stored
            idat_done = idat_done or bool(parts)
        pos = end
    return None


def _unfilter(filtered: np.ndarray, filters: np.ndarray, sample_bytes: int) -> np.ndarray | None:
    """The rows' bytes with their None, Sub and Up filters undone (the PNG
    specification, section 9.2), ``(height, width * sample_bytes)`` uint8; None
    for more than :data:`MAX_UP_RUNS` runs of Up rows."""
    sub, up = filters == _SUB, filters == _UP
    if sub.all():
        return _running_sums(filtered, sample_bytes)
    out = filtered.copy()
    if sub.any():
        out[sub] = _running_sums(filtered[sub], sample_bytes)
    if up.any():
        starts = np.flatnonzero(up & ~np.concatenate(([False], up[:-1])))
        ends = np.flatnonzero(up & ~np.concatenate((up[1:], [False]))) + 1
        if starts.size > MAX_UP_RUNS:
            return None
        for start, end in zip(starts, ends):
            run = np.cumsum(filtered[start:end], axis=0, dtype=np.uint8)
            if start:
                run += out[start - 1]
            out[start:end] = run
    return out


def _running_sums(rows: np.ndarray, sample_bytes: int) -> np.ndarray:
    """Each row's running sums modulo 256, each of the `sample_bytes` bytes of a
    sample summed with the same byte of the samples to its left."""
    height, stride = rows.shape
    out = np.empty((height, stride), np.uint8)
    width = stride // sample_bytes
    band = max(1, _INT32_MAX // (255 * (width + 1)) - 1)
    for lane in range(sample_bytes):
        for top in range(0, height, band):
            part = rows[top:top + band, lane::sample_bytes]
            sums = cv2.integral(part if sample_bytes == 1 else np.ascontiguousarray(part), sdepth=cv2.CV_32S)
            low = sums.view(np.uint8).reshape(sums.shape[0], sums.shape[1], 4)[:, 1:, _LOW_BYTE]
            np.subtract(low[1:], low[:-1], out=out[top:top + band, lane::sample_bytes])
    return out
