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
from numba import njit

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import PathLike
from ibik_pin.io.native_output import captured_native_stderr

__all__ = ["IMAGE_SUFFIXES", "decodes_silently", "list_mask_files", "read_image", "read_mask"]

#: The file suffixes read as images (any case).
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"})


def read_image(path: Path, flags: int, what: str, quiet_decoder: bool = False) -> np.ndarray:
    """An image file decoded by OpenCV, what its decoder prints to stderr quoted in the error.

    `quiet_decoder`: the files of this source decode without a word (decodes_silently on one of
    them), so the decoder's stderr is caught only when a decode fails, to quote it. Catching it
    means pointing the process's file descriptor 2 elsewhere for the decode: in a thread that
    reads ahead of the solver, that would also swallow what the main thread prints meanwhile, and
    its half-dozen system calls each hand the GIL over (ibik_pin.tracking.frame_images). A file that
    then fails to decode may have the decoder's own line printed before the error.

    Raises:
        FileFormatError: naming `what` ("mask", "background"), when the file is missing or cannot be
            decoded.
    """
    if not path.is_file():
        raise FileFormatError(f"{what} file '{path}': expected a readable image, found "
                              + ("no such file" if not path.exists() else "not a regular file"))
    if quiet_decoder:
        image = cv2.imread(str(path), flags)
        if image is not None:
            return image
    with captured_native_stderr() as decoder:
        image = cv2.imread(str(path), flags)
    if image is None:
        said = f" ({decoder.first_line()})" if decoder.first_line() else ""
        raise FileFormatError(f"{what} file '{path}': expected a readable image, OpenCV cannot decode it{said}")
    return image


def decodes_silently(path: Path) -> bool:
    """Whether OpenCV decodes the image file and its decoder prints nothing (libpng warns on, for
    example, a colour profile it finds wrong: a folder of such files would print a line a frame)."""
    with captured_native_stderr() as decoder:
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return image is not None and not decoder.text.strip()


def read_mask(path: PathLike, expected_size: tuple[int, int] | None = None, quiet_decoder: bool = False) -> np.ndarray:
    """A silhouette mask from an image file.

    The image is read as grey levels; a 0/255 mask (also after JPEG compression) is thresholded
    at mid-grey, a 0/1 label image (maximum <= 127) at non-zero.

    Args:
        path: image file (png, jpg, bmp, tif, ...).
        expected_size: (width, height) [px] the mask must have, or None.
        quiet_decoder: see read_image.

    Returns:
        (H, W) bool mask, True = person.

    Raises:
        FileFormatError: the file is missing or OpenCV cannot decode it.
        InputError: the size differs from ``expected_size``.
    """
    path = Path(path)
    image = read_image(path, cv2.IMREAD_GRAYSCALE, "mask", quiet_decoder)
    found = (image.shape[1], image.shape[0])
    if expected_size is not None and tuple(int(s) for s in expected_size) != found:
        raise InputError(
            f"mask file '{path}': expected size (w, h) = {tuple(int(s) for s in expected_size)}, found (w, h) = {found}"
        )
    return _thresholded(image)


@njit(cache=True, nogil=True)
def _thresholded(image):
    """image > 127 when some pixel exceeds 127, else image > 0: one compiled call for numpy's two
    passes (a mask read beside the solver gives up the GIL once, not twice)."""
    threshold = 0
    for value in image.ravel():
        if value > 127:
            threshold = 127
            break
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
