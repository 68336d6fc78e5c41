"""Silhouette masks on disk: one image per frame, non-zero = person.

A camera's masks are the image files of one folder, in the natural order of their names
(``frame2`` before ``frame10``); each is read as grey levels and thresholded, so 0/255 masks
(also JPEG-compressed ones) and 0/1 label images both work.
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import PathLike
from ibik_pin.io.native_output import captured_native_stderr
from ibik_pin.io.png import decode_grey_png

__all__ = ["IMAGE_SUFFIXES", "list_mask_files", "read_image", "read_mask"]

#: The file suffixes read as images (any case).
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"})


def read_image(path: Path, flags: int, what: str) -> np.ndarray:
    """An image file decoded by OpenCV, what its decoder prints to stderr quoted in the error; read
    as grey levels, an 8-bit grey PNG (most masks) is decoded by io.png instead, to the same pixels.

    Raises:
        FileFormatError: naming `what` ("mask", "background"), when the file is missing or cannot be
            decoded.
    """
    if not path.is_file():
        raise FileFormatError(f"{what} file '{path}': expected a readable image, found "
                              + ("no such file" if not path.exists() else "not a regular file"))
    try:
        data = path.read_bytes()
    except OSError as error:
        raise FileFormatError(f"{what} file '{path}': expected a readable image, "
                              f"cannot read it ({error.strerror})") from None
    if not data:
        raise FileFormatError(f"{what} file '{path}': expected a readable image, found an empty file")
    if flags == cv2.IMREAD_GRAYSCALE:
        image = decode_grey_png(data, f"{what} file '{path}'")
        if image is not None:
            return image
    with captured_native_stderr() as decoder:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if image is None:
        said = f" ({decoder.first_line()})" if decoder.first_line() else ""
        raise FileFormatError(f"{what} file '{path}': expected a readable image, OpenCV cannot decode it{said}")
    return image


def read_mask(path: PathLike, expected_size: tuple[int, int] | None = None) -> np.ndarray:
    """A silhouette mask from an image file.

    The image is read as grey levels; a 0/255 mask (also after JPEG compression) is thresholded
    at mid-grey, a 0/1 label image (maximum <= 127) at non-zero.

    Args:
        path: image file (png, jpg, bmp, tif, ...).
        expected_size: (width, height) [px] the mask must have, or None.

    Returns:
        (H, W) bool mask, True = person.

    Raises:
        FileFormatError: the file is missing or OpenCV cannot decode it.
        InputError: the size differs from ``expected_size``.
    """
    path = Path(path)
    image = read_image(path, cv2.IMREAD_GRAYSCALE, "mask")
    found = (image.shape[1], image.shape[0])
    if expected_size is not None and tuple(int(s) for s in expected_size) != found:
        raise InputError(
            f"mask file '{path}': expected size (w, h) = {tuple(int(s) for s in expected_size)}, found (w, h) = {found}"
        )
    threshold = 127 if image.max() > 127 else 0
    return image > threshold


def _natural_key(path: Path) -> list:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def list_mask_files(folder: PathLike) -> list[Path]:
    """Image files of a folder (png, jpg, jpeg, bmp, tif, tiff, any case), sorted by file name.

    Numbers in names compare as numbers (``frame2`` before ``frame10``).

    Raises:
        FileFormatError: the folder does not exist or holds no image file.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileFormatError(f"mask folder '{folder}': expected a directory, found none")
    files = [path for path in folder.iterdir() if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES]
    if not files:
        raise FileFormatError(
            f"mask folder '{folder}': expected image files ({', '.join(sorted(IMAGE_SUFFIXES))}), found none"
        )
    return sorted(files, key=_natural_key)
