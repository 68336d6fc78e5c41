"""Silhouette masks on disk: one image per frame.

A camera's masks are the image files of one folder, in the natural order of their names
(``frame2`` before ``frame10``). The conventions users' tools write are recognised, per file:

- a grey image, 8 or 16 bits: 0/255 (0/65535) masks, also after JPEG compression, are thresholded
  at mid-range; 0/1 label images (no value above mid-range) at non-zero;
- a colour image: its grey levels, as above;
- an image with an alpha channel that is not uniform: the alpha channel is the silhouette
  (thresholded at mid-range); a uniform alpha (an opaque RGBA export) is ignored;
- a float image (TIFF): values in [0, 1], thresholded at 0.5.

A label image with several non-zero labels holds several people or parts, and is refused by name:
which label is the subject cannot be guessed.
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import PathLike, as_path
from ibik_pin.io.png import decode_grey_png
from ibik_pin.native_output import captured_native_stderr

__all__ = ["IMAGE_SUFFIXES", "decode_mask", "list_mask_files", "mask_convention", "read_image", "read_mask"]

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
    if flags in (cv2.IMREAD_GRAYSCALE, cv2.IMREAD_UNCHANGED):  # the same pixels for a grey PNG
        image = decode_grey_png(data, f"{what} file '{path}'")
        if image is not None:
            return image
    with captured_native_stderr() as decoder:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if image is None:
        said = f" ({decoder.first_line()})" if decoder.first_line() else ""
        raise FileFormatError(f"{what} file '{path}': expected a readable image, OpenCV cannot decode it{said}")
    return image


def _check_expected_size(expected_size: object) -> tuple[int, int] | None:
    """`expected_size` as (width, height) ints, or InputError naming the value received."""
    if expected_size is None:
        return None
    sides = tuple(expected_size) if isinstance(expected_size, (tuple, list, np.ndarray)) else ()
    if len(sides) != 2 or not all(isinstance(side, (int, np.integer)) and not isinstance(side, bool) and side > 0
                                  for side in sides):
        raise InputError(f"read_mask: expected_size: expected (width, height) as two positive whole numbers "
                         f"of pixels, found {expected_size!r}")
    return int(sides[0]), int(sides[1])


def _binary(values: np.ndarray, full_scale: float, where: str) -> tuple[np.ndarray, str]:
    """A one-channel image as a mask: thresholded at mid-range when it reaches above it, else a label
    image (non-zero = person), refused when it holds several non-zero labels."""
    if values.dtype.kind == "f":
        return values > 0.5, "float image, thresholded at 0.5"
    peak = int(values.max()) if values.size else 0
    if peak > full_scale / 2:
        return values > full_scale // 2, f"{values.dtype.itemsize * 8}-bit mask, thresholded at mid-range"
    labels = np.unique(values[values != 0]) if peak > 1 else np.arange(1, peak + 1)
    if labels.size > 1:
        shown = ", ".join(str(int(label)) for label in labels[:5]) + (", ..." if labels.size > 5 else "")
        raise InputError(f"{where}: expected a mask of one person (0 and one other value), found a label image "
                         f"with {labels.size} labels ({shown}); write the subject's label alone")
    return values != 0, f"{values.dtype.itemsize * 8}-bit label image, non-zero = person"


def decode_mask(image: np.ndarray, where: str = "mask") -> tuple[np.ndarray, str]:
    """A decoded image (as OpenCV's IMREAD_UNCHANGED gives it) as a silhouette, and the convention read.

    Args:
        image: (H, W) grey, (H, W, 3) BGR, (H, W, 2) grey + alpha or (H, W, 4) BGRA; uint8, uint16
            or float.
        where: what to name in an error (the file).

    Returns:
        (H, W) bool mask, True = person; the convention as a phrase (see the module docstring).

    Raises:
        InputError: a label image with several labels, or an array that is no image.
    """
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (2, 3, 4))):
        raise InputError(f"{where}: expected a grey, colour or colour + alpha image, found an array of shape "
                         f"{image.shape}")
    if image.dtype.kind not in "uf":
        raise InputError(f"{where}: expected 8-bit, 16-bit or float pixels, found {image.dtype}")
    full_scale = 1.0 if image.dtype.kind == "f" else float(np.iinfo(image.dtype).max)
    channels = image
    if channels.ndim == 3 and channels.shape[2] in (2, 4):
        alpha = channels[..., -1]
        if alpha.size and alpha.min() != alpha.max():
            return alpha > full_scale / 2, "alpha channel, thresholded at mid-range"
        channels = channels[..., :-1]
    if channels.ndim == 3:
        grey = channels[..., 0] if channels.shape[2] == 1 else cv2.cvtColor(
            np.ascontiguousarray(channels), cv2.COLOR_BGR2GRAY)  # grey + alpha: the grey alone
        mask, convention = _binary(grey, full_scale, where)
        return mask, "colour image read as grey: " + convention
    return _binary(channels, full_scale, where)


def _read_decoded(path: PathLike, expected_size: object) -> tuple[np.ndarray, str]:
    size = _check_expected_size(expected_size)
    path = as_path(path)
    where = f"mask file '{path}'"
    image = read_image(path, cv2.IMREAD_UNCHANGED, "mask")
    found = (image.shape[1], image.shape[0])
    if size is not None and size != found:
        raise InputError(f"{where}: expected size (w, h) = {size}, found (w, h) = {found}")
    return decode_mask(image, where)


def read_mask(path: PathLike, expected_size: tuple[int, int] | None = None) -> np.ndarray:
    """A silhouette mask from an image file, in any of the conventions of the module docstring.

    Args:
        path: image file (png, jpg, bmp, tif, ...).
        expected_size: (width, height) [px] the mask must have, or None.

    Returns:
        (H, W) bool mask, True = person.

    Raises:
        FileFormatError: the file is missing or OpenCV cannot decode it.
        InputError: the size differs from ``expected_size``, ``expected_size`` is not two positive
            whole numbers, or the image is a label image with several labels.
    """
    return _read_decoded(path, expected_size)[0]


def mask_convention(path: PathLike) -> str:
    """How `read_mask` reads this file, as a phrase (e.g. "alpha channel, thresholded at mid-range"),
    to state in a run's report. Raises as `read_mask`."""
    return _read_decoded(path, None)[1]


def _natural_key(path: Path) -> list:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def list_mask_files(folder: PathLike) -> list[Path]:
    """Image files of a folder (png, jpg, jpeg, bmp, tif, tiff, any case), sorted by file name.

    Numbers in names compare as numbers (``frame2`` before ``frame10``).

    Raises:
        FileFormatError: the folder does not exist or holds no image file.
    """
    folder = as_path(folder, "folder")
    if not folder.is_dir():
        raise FileFormatError(f"mask folder '{folder}': expected a directory, found none")
    files = [path for path in folder.iterdir() if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES]
    if not files:
        raise FileFormatError(
            f"mask folder '{folder}': expected image files ({', '.join(sorted(IMAGE_SUFFIXES))}), found none"
        )
    return sorted(files, key=_natural_key)
