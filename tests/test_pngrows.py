"""vision_torsion.pngrows against OpenCV's decoder (libpng): the same samples for
every PNG it decodes, and None (OpenCV decides) for every other or damaged one.

The files are built here, chunk by chunk, so each filter, chunk order and kind of
damage is chosen, not left to an encoder."""

import struct
import zlib

import cv2
import numpy as np
import pytest

from vision_torsion.errors import ImageReadError
from vision_torsion.images import decode_image
from vision_torsion.pngrows import MAX_CHUNKS, MAX_UP_RUNS, decode_grey_png

NONE, SUB, UP, AVERAGE, PAETH = range(5)


def chunk(kind: bytes, body: bytes, *, crc: int | None = None) -> bytes:
    crc = zlib.crc32(kind + body) if crc is None else crc
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)


def filtered_rows(samples: np.ndarray, filters) -> bytes:
    """The PNG rows of `samples` (uint8 or uint16, 2-D) with each row's filter
    applied: 0 None, 1 Sub, 2 Up (the others are written unfiltered under their
    filter byte, a valid file whose samples OpenCV computes)."""
    data = samples.astype(">u2").view(np.uint8) if samples.dtype == np.uint16 else samples
    data = data.reshape(samples.shape[0], -1).astype(np.int16)
    step = 2 if samples.dtype == np.uint16 else 1
    out = []
    for i, f in enumerate(filters):
        row = data[i].copy()
        if f == SUB:
            row[step:] -= data[i, :-step]
        elif f == UP and i:
            row -= data[i - 1]
        out.append(bytes([f]) + (row % 256).astype(np.uint8).tobytes())
    return b"".join(out)


def png(samples, filters=None, *, extra_before=(), extra_after=(), idat_pieces=1, stream=None,
        ihdr=None) -> bytes:
    height, width = samples.shape
    depth = 16 if samples.dtype == np.uint16 else 8
    filters = [SUB] * height if filters is None else filters
    ihdr = struct.pack(">IIBBBBB", width, height, depth, 0, 0, 0, 0) if ihdr is None else ihdr
    stream = zlib.compress(filtered_rows(samples, filters), 6) if stream is None else stream
    cuts = np.linspace(0, len(stream), idat_pieces + 1).astype(int)
    idats = b"".join(chunk(b"IDAT", stream[a:b]) for a, b in zip(cuts[:-1], cuts[1:]))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + b"".join(extra_before) + idats
            + b"".join(extra_after) + chunk(b"IEND", b""))


def opencv(raw: bytes) -> np.ndarray:
    arr = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED)
    assert arr is not None
    return arr[:, :, 0] if arr.ndim == 3 else arr  # grey + alpha (a tRNS chunk): the grey


def samples(shape, dtype, seed):
    rng = np.random.default_rng(seed)
    top = 65535 if dtype == np.uint16 else 255
    return rng.integers(0, top + 1, shape).astype(dtype)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("shape", [(8, 8), (37, 91), (300, 401)])
def test_opencvs_own_pngs_decode_to_opencvs_samples(shape, dtype):
    image = samples(shape, dtype, seed=shape[1])
    ok, encoded = cv2.imencode(".png", image)
    raw = encoded.tobytes()
    got = decode_grey_png(raw)
    assert got is not None  # OpenCV's rows are Sub: this decoder's case
    assert got.dtype == dtype and got.flags.c_contiguous
    np.testing.assert_array_equal(got, opencv(raw))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_rows_of_mixed_none_sub_and_up_filters(dtype, seed):
    image = samples((60, 33), dtype, seed)
    filters = np.random.default_rng(seed).choice([NONE, SUB, UP], size=60)
    filters[:3] = [UP, UP, NONE]  # an Up run at the top (its prior row is zeros)
    raw = png(image, filters, idat_pieces=5)
    got = decode_grey_png(raw)
    np.testing.assert_array_equal(got, image)
    np.testing.assert_array_equal(got, opencv(raw))


def test_ancillary_chunks_leave_the_samples_as_stored():
    image = samples((20, 30), np.uint8, 4)
    raw = png(image, extra_before=[chunk(b"gAMA", struct.pack(">I", 45455)), chunk(b"sBIT", b"\x08"),
                                   chunk(b"tRNS", b"\x00\x07")],
              extra_after=[chunk(b"tEXt", b"Comment\x00after the data")])
    np.testing.assert_array_equal(decode_grey_png(raw), opencv(raw))


def test_a_tall_image_is_summed_in_bands_and_decodes_the_same():
    # 8000 px rows: a 32-bit running sum of 1,053 such rows could pass 2**31
    image = samples((1100, 8000), np.uint8, 5)
    ok, encoded = cv2.imencode(".png", image)
    got = decode_grey_png(encoded.tobytes())
    np.testing.assert_array_equal(got, image)


@pytest.mark.parametrize("filter_", [AVERAGE, PAETH])
def test_average_and_paeth_rows_are_left_to_opencv(filter_):
    image = samples((10, 12), np.uint8, 6)
    filters = [SUB] * 10
    filters[4] = filter_
    raw = png(image, filters)
    assert decode_grey_png(raw) is None
    np.testing.assert_array_equal(decode_image(raw, name="a.png", keep_integers=True).data, opencv(raw))


@pytest.mark.parametrize("colour, depth, interlace", [(2, 8, 0), (4, 8, 0), (0, 8, 1), (0, 4, 0)])
def test_other_kinds_of_png_are_left_to_opencv(colour, depth, interlace):
    image = samples((10, 12), np.uint8, 7)
    ihdr = struct.pack(">IIBBBBB", 12, 10, depth, colour, 0, 0, interlace)
    assert decode_grey_png(png(image, ihdr=ihdr)) is None


def test_more_runs_of_up_rows_than_the_limit_are_left_to_opencv():
    rows = 2 * MAX_UP_RUNS + 2
    image = samples((rows, 9), np.uint8, 11)
    raw = png(image, [SUB, UP] * (MAX_UP_RUNS + 1))
    assert decode_grey_png(raw) is None
    np.testing.assert_array_equal(decode_image(raw, name="a.png", keep_integers=True).data, image)
    within = png(image, [SUB, UP] * MAX_UP_RUNS + [SUB, SUB])
    np.testing.assert_array_equal(decode_grey_png(within), image)


def test_more_chunks_than_the_limit_are_left_to_opencv():
    image = samples((16, 16), np.uint8, 12)
    stream = zlib.compress(filtered_rows(image, [SUB] * 16))
    pieces = [chunk(b"tEXt", b"k\x00v")] * MAX_CHUNKS
    raw = png(image, stream=stream, extra_before=pieces)
    assert decode_grey_png(raw) is None
    np.testing.assert_array_equal(decode_image(raw, name="a.png", keep_integers=True).data, image)
    fewer = png(image, stream=stream, extra_before=pieces[:MAX_CHUNKS - 4])  # IHDR, IDAT, IEND
    np.testing.assert_array_equal(decode_grey_png(fewer), image)


def test_a_png_with_a_palette_chunk_is_left_to_opencv():
    image = samples((10, 12), np.uint8, 8)
    assert decode_grey_png(png(image, extra_before=[chunk(b"PLTE", b"\x00\x00\x00")])) is None


def test_image_data_split_by_another_chunk_is_left_to_opencv():
    image = samples((10, 12), np.uint8, 9)
    stream = zlib.compress(filtered_rows(image, [SUB] * 10))
    raw = png(image, stream=stream[:20], extra_after=[chunk(b"tEXt", b"a\x00b"), chunk(b"IDAT", stream[20:])])
    assert decode_grey_png(raw) is None


def damaged_files():
    image = samples((16, 16), np.uint8, 10)
    good = zlib.compress(filtered_rows(image, [SUB] * 16))
    bad_crc = png(image)
    at = bad_crc.index(b"IDAT")
    bad_crc = bad_crc[:at + 4 + len(good)] + b"\x00\x00\x00\x00" + bad_crc[at + 8 + len(good):]
    longer = zlib.compress(filtered_rows(image, [SUB] * 16) + b"\x00" * 17)
    wrong_sum = good[:-4] + bytes(b ^ 0xFF for b in good[-4:])
    return {
        "a chunk's CRC does not match": bad_crc,
        "the stream ends early": png(image, stream=good[:-30]),
        "the stream holds more than the rows": png(image, stream=longer),
        "the stream's checksum is wrong": png(image, stream=wrong_sum),
        "the stream's checksum is missing": png(image, stream=good[:-4]),
        "bytes follow the stream's end": png(image, stream=good + b"\x00\x01"),
        "a row filter byte is 9": png(image, stream=zlib.compress(b"\x09" + filtered_rows(image, [SUB] * 16)[1:])),
        "no IEND chunk": png(image)[:-12],
        "a chunk claims more bytes than the file has": png(image)[:40] + struct.pack(">I", 10**6) + b"IDAT",
    }


@pytest.mark.parametrize("why", list(damaged_files()))
def test_a_damaged_png_is_left_to_opencv(why):
    raw = damaged_files()[why]
    assert decode_grey_png(raw) is None
    try:
        got = decode_image(raw, name="damaged.png", keep_integers=True).data
    except ImageReadError:
        return  # refused, by the checks before decoding or by OpenCV
    np.testing.assert_array_equal(got, opencv(raw))  # or OpenCV's samples
