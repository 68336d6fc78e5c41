"""The grey-PNG fast path of mask reading (ibik_pin/io/png.py) against OpenCV's decoder."""

import struct
import zlib

import cv2
import numpy as np
import pytest

from ibik_pin.exceptions import FileFormatError
from ibik_pin.io.masks import read_mask
from ibik_pin.io.png import decode_grey_png


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _paeth(left: int, up: int, corner: int) -> int:
    estimate = left + up - corner
    distances = (abs(estimate - left), abs(estimate - up), abs(estimate - corner))
    return (left, up, corner)[distances.index(min(distances))]


def _filtered_row(image: np.ndarray, r: int, kind: int) -> bytes:
    """Row r of an 8-bit grey image under PNG filter `kind` (the PNG specification's definitions)."""
    row = image[r].astype(int)
    up = image[r - 1].astype(int) if r > 0 else np.zeros_like(row)
    left = np.concatenate([[0], row[:-1]])
    corner = np.concatenate([[0], up[:-1]])
    if kind == 0:
        predicted = np.zeros_like(row)
    elif kind == 1:
        predicted = left
    elif kind == 2:
        predicted = up
    elif kind == 3:
        predicted = (left + up) // 2
    else:
        predicted = np.array([_paeth(a, b, c) for a, b, c in zip(left, up, corner, strict=True)])
    return bytes([kind]) + bytes(((row - predicted) % 256).astype(np.uint8))


def _png(image: np.ndarray, filters, colour: int = 0, depth: int = 8, interlace: int = 0,
         extra: bytes = b"") -> bytes:
    """A PNG file of an 8-bit grey image, row r filtered with filters[r % len(filters)]."""
    height, width = image.shape
    raw = b"".join(_filtered_row(image, r, filters[r % len(filters)]) for r in range(height))
    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, interlace)
    compressed = zlib.compress(raw, 9)
    # Two IDAT chunks: the stream may be split anywhere.
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + extra + _chunk(b"IDAT", compressed[:5])
            + _chunk(b"IDAT", compressed[5:]) + _chunk(b"IEND", b""))


def _opencv(data: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)


@pytest.mark.parametrize("filters", [[0], [1], [2], [3], [4], [4, 3, 2, 1, 0]])
def test_every_row_filter_is_undone_to_the_pixels_opencv_reads(filters):
    rng = np.random.default_rng(7)
    image = rng.integers(0, 256, (23, 31), dtype=np.uint8)
    image[5:15, 3:20] = 255  # flat runs as well as noise
    data = _png(image, filters)
    decoded = decode_grey_png(data, "x.png")
    assert decoded is not None and decoded.dtype == np.uint8
    np.testing.assert_array_equal(decoded, image)
    np.testing.assert_array_equal(decoded, _opencv(data))


@pytest.mark.parametrize("strategy", [cv2.IMWRITE_PNG_STRATEGY_DEFAULT, cv2.IMWRITE_PNG_STRATEGY_FILTERED,
                                      cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY, cv2.IMWRITE_PNG_STRATEGY_RLE])
def test_pngs_written_by_opencv_decode_to_its_own_reading(strategy):
    rng = np.random.default_rng(3)
    for compression in (0, 1, 6, 9):
        height, width = rng.integers(1, 90, 2)
        masks = (rng.random((height, width)) < 0.4).astype(np.uint8) * 255
        smooth = cv2.GaussianBlur(rng.random((height, width)).astype(np.float32) * 255, (0, 0), 2).astype(np.uint8)
        for image in (masks, smooth):
            ok, encoded = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, compression,
                                                       cv2.IMWRITE_PNG_STRATEGY, strategy])
            assert ok
            np.testing.assert_array_equal(decode_grey_png(encoded.tobytes(), "x.png"), image)


def test_other_kinds_of_image_are_left_to_opencv():
    image = np.zeros((4, 6), np.uint8)
    ok, colour = cv2.imencode(".png", np.zeros((4, 6, 3), np.uint8))
    ok16, deep = cv2.imencode(".png", np.zeros((4, 6), np.uint16))
    ok_jpeg, jpeg = cv2.imencode(".jpg", image)
    assert ok and ok16 and ok_jpeg
    assert decode_grey_png(colour.tobytes(), "x") is None
    assert decode_grey_png(deep.tobytes(), "x") is None
    assert decode_grey_png(jpeg.tobytes(), "x") is None
    assert decode_grey_png(_png(image, [0], interlace=1), "x") is None
    assert decode_grey_png(_png(image, [0], extra=_chunk(b"eXIf", b"MM\x00*")), "x") is None


def test_a_damaged_grey_png_is_one_file_format_error_naming_the_file():
    image = np.arange(48, dtype=np.uint8).reshape(6, 8)
    good = _png(image, [1])
    idat = good.index(b"IDAT")
    wrong_crc = bytearray(good)
    wrong_crc[idat + 4] ^= 0xFF  # a byte of the first IDAT's body, its CRC left as it was
    raw = bytearray(b"".join(_filtered_row(image, r, 1) for r in range(6)))
    raw[0] = 9
    header = struct.pack(">IIBBBBB", 8, 6, 8, 0, 0, 0, 0)
    unknown_filter = (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(bytes(raw)))
                      + _chunk(b"IEND", b""))
    too_short = (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(bytes(raw[:-8])))
                 + _chunk(b"IEND", b""))
    not_deflate = (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", b"not a zlib stream")
                   + _chunk(b"IEND", b""))
    cases = {
        "ends before": good[:idat + 20],
        "cut short": good[:-9] + struct.pack(">I", 99) + b"IEND",
        "CRC": bytes(wrong_crc),
        "filter type": unknown_filter,
        "holds": too_short,
        "does not inflate": not_deflate,
        "start with its IHDR": b"\x89PNG\r\n\x1a\n" + _chunk(b"IDAT", b""),
    }
    for said, data in cases.items():
        with pytest.raises(FileFormatError, match=f"^mask file 'm.png': .*{said}"):
            decode_grey_png(data, "mask file 'm.png'")


def test_read_mask_gives_the_same_mask_from_a_grey_and_a_colour_png(tmp_path):
    rng = np.random.default_rng(11)
    mask = rng.random((40, 50)) < 0.3
    grey, colour = tmp_path / "grey.png", tmp_path / "colour.png"
    cv2.imwrite(str(grey), mask.astype(np.uint8) * 255)
    cv2.imwrite(str(colour), np.repeat(mask[..., None], 3, axis=2).astype(np.uint8) * 255)
    np.testing.assert_array_equal(read_mask(grey), mask)
    np.testing.assert_array_equal(read_mask(colour), mask)
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    with pytest.raises(FileFormatError, match="empty file"):
        read_mask(empty)
