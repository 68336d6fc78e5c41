"""Overlay videos: the estimated skeleton drawn over each camera's silhouettes (MP4).

One video per camera, written frame by frame (a long sequence is never held in memory) with
OpenCV's ``mp4v`` codec, atomically: the image or the silhouette as background, the silhouette
blended in colour, the projected skeleton on top.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import write_atomically
from ibik_pin.viz.drawing import draw_skeleton, overlay_mask

__all__ = ["write_overlay_video"]

# Mask pixels drawn as the background when there is no image: grey level (0-255).
_MASK_GREY = 150


# Stands for the item of an input that ended before the others.
_MISSING = object()


def write_overlay_video(
    path: str | os.PathLike[str],
    frames_bgr: Iterable[np.ndarray] | None,
    skeletons: Iterable[tuple[np.ndarray, np.ndarray]],
    fps: float,
    masks: Iterable[np.ndarray] | None = None,
    skeleton_color: tuple[int, int, int] = (0, 255, 0),
    mask_color: tuple[int, int, int] = (0, 0, 255),
) -> int:
    """An MP4 video (``mp4v``) of the projected skeleton over the images and silhouettes.

    Each video frame is the image, with the silhouette mask blended over it in ``mask_color``
    if masks are given, and the skeleton drawn with :func:`~ibik_pin.viz.drawing.draw_skeleton`.
    Without images (``frames_bgr=None``) the mask itself is the background, drawn grey on black.
    The inputs are consumed one frame at a time (generators are fine: a long video is never
    held in memory) and must yield as many items each.

    Args:
        path: The .mp4 file to write.
        frames_bgr: Images, each (H, W, 3) BGR or (H, W) grey, uint8, all of one size; or None.
        skeletons: Per frame, the segments' start and end pixels, shapes (S, 2) and (S, 2) [px];
            segments with a non-finite end are not drawn.
        fps: Frames per second of the video [Hz].
        masks: Per frame, the (H, W) silhouette (bool, or non-zero = inside); or None.
        skeleton_color: BGR colour of the skeleton.
        mask_color: BGR colour blended over the silhouette (opacity 0.4).

    Returns:
        The number of frames written.

    Raises:
        InputError: Neither images nor masks, no frame, a frame of another size or kind, the
            inputs of different lengths, or ``fps`` not positive.
        FileFormatError: OpenCV cannot open a video writer for ``path``.
    """
    if not np.isfinite(fps) or fps <= 0.0:
        raise InputError(f"fps: expected a positive number [Hz], got {fps}")
    if frames_bgr is None and masks is None:
        raise InputError("frames_bgr, masks: expected images, masks or both, got neither")
    given: dict[str, Iterable[object] | None] = {"skeletons": skeletons, "frames_bgr": frames_bgr, "masks": masks}
    sources = {name: iter(source) for name, source in given.items() if source is not None}

    def write(temporary: Path) -> int:
        writer = None
        try:
            items_per_frame = itertools.zip_longest(*sources.values(), fillvalue=_MISSING)
            for index, items in enumerate(items_per_frame):
                item = dict(zip(sources, items, strict=True))
                ended = [name for name, value in item.items() if value is _MISSING]
                if ended:
                    longer = [name for name in item if name not in ended]
                    raise InputError(
                        f"{', '.join(ended)}: ended after {index} frames, but "
                        f"{', '.join(longer)} went on: expected as many frames in each"
                    )
                image = _overlay_frame(index, item, skeleton_color, mask_color)
                if writer is None:
                    size = (image.shape[1], image.shape[0])
                    writer = _open_video_writer(temporary, path, fps, size)
                elif (image.shape[1], image.shape[0]) != size:
                    raise InputError(
                        f"frame {index}: expected {size[0]} x {size[1]} px like frame 0, got "
                        f"{image.shape[1]} x {image.shape[0]} px"
                    )
                writer.write(image)
            if writer is None:
                raise InputError(
                    f"{', '.join(sources)}: expected at least one frame, got none"
                )
            return index + 1
        finally:
            if writer is not None:
                writer.release()

    return write_atomically(path, write)


def _overlay_frame(
    index: int,
    item: dict[str, object],
    skeleton_color: tuple[int, int, int],
    mask_color: tuple[int, int, int],
) -> np.ndarray:
    """Frame `index` of an overlay video: image or grey mask, coloured mask, skeleton."""
    mask = None
    if "masks" in item:
        mask = np.asarray(item["masks"])
        if mask.ndim != 2:
            raise InputError(
                f"masks: expected (H, W) silhouettes, got shape {mask.shape} at frame {index}"
            )
        mask = mask != 0
    if "frames_bgr" in item:
        image = np.asarray(item["frames_bgr"])
        is_bgr = image.ndim == 3 and image.shape[2] == 3
        if image.dtype != np.uint8 or not (image.ndim == 2 or is_bgr):
            raise InputError(
                f"frames_bgr: expected (H, W, 3) BGR or (H, W) grey uint8 images, got shape "
                f"{image.shape} and dtype {image.dtype} at frame {index}"
            )
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image
        if mask is not None:
            if mask.shape != image.shape[:2]:
                raise InputError(
                    f"masks: expected shape {image.shape[:2]} like the image, got {mask.shape} "
                    f"at frame {index}"
                )
            image = overlay_mask(image, mask, color=mask_color, alpha=0.4)
    else:
        assert mask is not None  # write_overlay_video refuses neither images nor masks
        image = np.zeros((*mask.shape, 3), np.uint8)
        image[mask] = _MASK_GREY
    skeleton = item["skeletons"]
    if not isinstance(skeleton, (tuple, list)) or len(skeleton) != 2:
        raise InputError(
            f"skeletons: expected a pair (starts (S, 2), ends (S, 2)) [px] at frame {index}, "
            f"got {type(skeleton).__name__}"
        )
    return draw_skeleton(image, skeleton[0], skeleton[1], color=skeleton_color)


def _open_video_writer(
    temporary: Path, path: str | os.PathLike[str], fps: float, size: tuple[int, int]
) -> cv2.VideoWriter:
    try:
        writer = cv2.VideoWriter(str(temporary), cv2.VideoWriter.fourcc(*"mp4v"), float(fps), size)
    except cv2.error as error:
        raise FileFormatError(f"{path}: OpenCV cannot write an mp4v video: {error}") from None
    if not writer.isOpened():
        writer.release()
        raise FileFormatError(
            f"{path}: OpenCV cannot open an mp4v video writer ({size[0]} x {size[1]} px at "
            f"{fps} fps); check the folder exists and is writable"
        )
    return writer
