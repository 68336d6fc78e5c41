"""A fast reader of 8-bit grey PNG files, the usual format of silhouette masks.

OpenCV decodes a 640 x 480 mask PNG in about 1.2 ms, half of it in zlib's inflate: a mask
compresses to a few kilobytes of long runs, which zlib copies byte by byte. zlib-ng inflates the
same stream in about 40 us, and the rows' PNG filters are undone in one compiled pass, so a
frame's masks no longer cost most of the time of the thread that prepares the support images.

Only the plainest kind of PNG is read here (8-bit greyscale, not interlaced, no EXIF orientation);
`decode_grey_png` returns None for any other, which the caller hands to OpenCV.
"""

from __future__ import annotations

import struct
from typing import cast

import numpy as np
from numba import njit
from zlib_ng import zlib_ng

from ibik_pin.exceptions import FileFormatError

__all__ = ["decode_grey_png"]

SIGNATURE = b"\x89PNG\r\n\x1a\n"
INFLATE_ERROR = cast(type[Exception], zlib_ng.error)  # the stubs do not declare it a class
GREY = 0  # IHDR colour type of greyscale without alpha


def decode_grey_png(data: bytes, name: str) -> np.ndarray | None:
    """The pixels (H, W) uint8 of an 8-bit greyscale, non-interlaced PNG file's bytes; None when
    the bytes are not a PNG of that kind (another format, depth or colour type).

    Raises:
        FileFormatError: naming `name`, when the file is such a PNG but damaged (a chunk cut short
            or with a wrong CRC, pixel data that does not inflate to the image's size, an unknown
            row filter).
    """
    if not data.startswith(SIGNATURE):
        return None
    view = memoryview(data)
    position = len(SIGNATURE)
    header: tuple[int, ...] | None = None
    pieces: list[memoryview] = []
    while True:
        if position + 8 > len(data):
            raise FileFormatError(f"{name}: the PNG ends before its IEND chunk")
        length, kind = struct.unpack_from(">I4s", data, position)
        end = position + 12 + length
        if end > len(data):
            raise FileFormatError(f"{name}: the PNG's {kind.decode('latin-1')!r} chunk is cut short")
        body = view[position + 8:end - 4]
        (crc,) = struct.unpack_from(">I", data, end - 4)
        if zlib_ng.crc32(body, zlib_ng.crc32(kind)) != crc:
            raise FileFormatError(f"{name}: the PNG's {kind.decode('latin-1')!r} chunk fails its CRC check")
        if header is None:
            if kind != b"IHDR" or length != 13:
                raise FileFormatError(f"{name}: the PNG does not start with its IHDR chunk")
            header = struct.unpack(">IIBBBBB", body)
            width, height, depth, colour, compression, filtering, interlace = header
            if (depth, colour, compression, filtering, interlace) != (8, GREY, 0, 0, 0) or width == 0 or height == 0:
                return None
        elif kind == b"IDAT":
            pieces.append(body)
        elif kind == b"eXIf":
            return None  # an orientation OpenCV would apply
        elif kind == b"IEND":
            break
        position = end
    row_bytes = width + 1  # each row starts with its filter type
    try:
        raw = zlib_ng.decompress(b"".join(pieces), bufsize=height * row_bytes + 1)
    except INFLATE_ERROR as error:
        raise FileFormatError(f"{name}: the PNG's pixel data does not inflate ({error})") from None
    if len(raw) != height * row_bytes:
        raise FileFormatError(f"{name}: the PNG's pixel data holds {len(raw)} bytes, "
                              f"expected {height * row_bytes} for {width} x {height} pixels")
    pixels = np.empty((height, width), np.uint8)
    if not _unfilter(np.frombuffer(raw, np.uint8).reshape(height, row_bytes), pixels):
        raise FileFormatError(f"{name}: the PNG has a row filter type outside 0-4")
    return pixels


@njit(cache=True, nogil=True)
def _unfilter(rows: np.ndarray, pixels: np.ndarray) -> bool:  # pragma: no cover - compiled
    """Undo the PNG row filters of one byte per pixel (rows (H, W + 1), the filter type first)
    into pixels (H, W); False on an unknown filter type. The row above the first and the pixel
    left of each row's first count as 0. One loop per filter type: a test per pixel cost as much
    as the rest of the decoding."""
    height, width = pixels.shape
    zeros = np.zeros(width, np.uint8)
    for r in range(height):
        kind = rows[r, 0]
        row = rows[r, 1:]
        out = pixels[r]
        up = pixels[r - 1] if r > 0 else zeros
        if kind == 0:
            out[:] = row
        elif kind == 1:
            left = np.uint8(0)
            for c in range(width):
                left = np.uint8(row[c] + left)
                out[c] = left
        elif kind == 2:
            for c in range(width):
                out[c] = np.uint8(row[c] + up[c])
        elif kind == 3:
            left_value = 0
            for c in range(width):
                left_value = (np.int32(row[c]) + ((left_value + np.int32(up[c])) >> 1)) & 255
                out[c] = np.uint8(left_value)
        elif kind == 4:
            left_value, corner = 0, 0
            for c in range(width):
                above = np.int32(up[c])
                estimate = left_value + above - corner
                to_left, to_up, to_corner = abs(estimate - left_value), abs(estimate - above), abs(estimate - corner)
                if to_left <= to_up and to_left <= to_corner:
                    predicted = left_value
                elif to_up <= to_corner:
                    predicted = above
                else:
                    predicted = corner
                left_value = (np.int32(row[c]) + predicted) & 255
                corner = above
                out[c] = np.uint8(left_value)
        else:
            return False
    return True
