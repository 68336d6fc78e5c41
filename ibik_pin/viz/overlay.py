"""Overlay videos: the estimated skeleton drawn over each camera's silhouettes (MP4, H.264).

One video per camera, written frame by frame (a long sequence is never held in memory) and
atomically: the image or the silhouette as background, the silhouette blended in colour, the
projected skeleton on top, the frame number and time in the top-left corner and a legend below it.

The video is H.264 (libx264, ``yuv420p``, ``+faststart``) in MP4, what browsers play: OpenCV's
wheels encode only ``mp4v``, which Chromium refuses (``MEDIA_ERR_SRC_NOT_SUPPORTED``), so the
frames go through PyAV, whose wheels ship FFmpeg with libx264. ``yuv420p`` needs an even width and
height: an odd frame gets one black column or row.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterable, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import cv2
import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import write_atomically
from ibik_pin.viz.drawing import draw_skeleton, overlay_mask

__all__ = ["VIDEO_CODEC", "write_overlay_video"]

#: The codec and pixel format of the overlays (what browsers decode).
VIDEO_CODEC = "h264"
VIDEO_PIXEL_FORMAT = "yuv420p"
# x264's constant rate factor: 23 is its default, visually clean for drawn lines on video.
_CRF = "23"
# x264 preset: "veryfast" encoded the Pose2Sim demo 3x faster than x264's default "medium", and smaller
# (0.59 against 0.68 MB; experiments/overlay_codecs.py, docs/results.md).
_PRESET = "veryfast"
# Mask pixels drawn as the background when there is no image: grey level (0-255).
_MASK_GREY = 150
# Caption text: white on a dark box, its height a fraction of the frame's (at least 9 px).
_TEXT_HEIGHT_FRACTION = 0.022


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
    frame_numbers: Sequence[int] | np.ndarray | None = None,
    times: Sequence[float] | np.ndarray | None = None,
) -> int:
    """An MP4 video (H.264) of the projected skeleton over the images and silhouettes.

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
        frame_numbers: The number shown for each frame (e.g. the TRC's Frame#); 1, 2, ... if None.
        times: The time shown for each frame [s]; frame index / fps if None.

    Returns:
        The number of frames written.

    Raises:
        InputError: Neither images nor masks, no frame, a frame of another size or kind, the
            inputs of different lengths, or ``fps`` not positive.
        InputError: also when the file cannot be written (missing folder, permissions, full disk).
        FileFormatError: FFmpeg cannot open an H.264 video for ``path``.
    """
    if not np.isfinite(fps) or fps <= 0.0:
        raise InputError(f"fps: expected a positive number [Hz], got {fps}")
    if frames_bgr is None and masks is None:
        raise InputError("frames_bgr, masks: expected images, masks or both, got neither")
    given: dict[str, Iterable[object] | None] = {"skeletons": skeletons, "frames_bgr": frames_bgr, "masks": masks}
    sources = {name: iter(source) for name, source in given.items() if source is not None}
    legend = [("estimated skeleton", skeleton_color)] + ([("silhouette", mask_color)] if masks is not None else [])

    def caption(index: int) -> str:
        number = frame_numbers[index] if frame_numbers is not None and index < len(frame_numbers) else index + 1
        time = times[index] if times is not None and index < len(times) else index / fps
        return f"frame {number}  t = {time:.3f} s"

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
                image = _draw_captions(image, caption(index), legend)
                if writer is None:
                    size = (image.shape[1], image.shape[0])
                    writer = _H264Writer(temporary, path, fps, size)
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
            writer.finish()
            return index + 1
        finally:
            if writer is not None:
                writer.close()

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
    return draw_skeleton(image, skeleton[0], skeleton[1], color=skeleton_color,
                         thickness=skeleton_thickness(image.shape[:2]))


def skeleton_thickness(image_size_hw: tuple[int, int]) -> int:
    """The skeleton's line width [px] for an image of (height, width) [px]: 2 px at 640 x 480, in
    proportion to the shorter side above it (4 px at 1088 x 1920), so lines read at any size."""
    return max(2, round(min(image_size_hw) / 240))


def _draw_captions(image: np.ndarray, caption: str, legend: list[tuple[str, tuple[int, int, int]]]) -> np.ndarray:
    """The frame with its caption (frame number, time) and the legend, top left, on dark boxes."""
    height = image.shape[0]
    font = cv2.FONT_HERSHEY_SIMPLEX
    text_px = max(9.0, _TEXT_HEIGHT_FRACTION * height)
    scale = text_px / 22.0  # FONT_HERSHEY_SIMPLEX at scale 1 is about 22 px tall
    thickness = max(1, round(text_px / 12.0))
    margin = max(2, round(text_px / 3.0))
    lines = [(caption, (255, 255, 255))] + [(f"-- {label}", color) for label, color in legend]
    y = margin
    for text, color in lines:
        (width, text_height), baseline = cv2.getTextSize(text, font, scale, thickness)
        cv2.rectangle(image, (0, y), (width + 2 * margin, y + text_height + baseline + margin), (0, 0, 0), -1)
        cv2.putText(image, text, (margin, y + text_height + margin // 2), font, scale, color, thickness, cv2.LINE_AA)
        y += text_height + baseline + margin
    return image


class _H264Writer:
    """Frames (H, W, 3) BGR uint8 in, an H.264 MP4 out (PyAV); padded to even sizes."""

    def __init__(self, temporary: Path, path: str | os.PathLike[str], fps: float, size: tuple[int, int]):
        self.size = size
        self.even_size = (size[0] + size[0] % 2, size[1] + size[1] % 2)
        try:
            self.container: Any = av.open(str(temporary), mode="w", format="mp4",
                                          options={"movflags": "+faststart"})
        except av.FFmpegError as error:
            if isinstance(error, OSError):
                raise  # write_atomically reports it as a file that cannot be written
            raise FileFormatError(
                f"{path}: FFmpeg cannot open an H.264 video ({size[0]} x {size[1]} px at {fps} fps): {error}"
            ) from None
        self.stream = self.container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
        self.stream.width, self.stream.height = self.even_size
        self.stream.pix_fmt = VIDEO_PIXEL_FORMAT
        self.stream.options = {"crf": _CRF, "preset": _PRESET}

    def write(self, image: np.ndarray) -> None:
        if self.even_size != self.size:
            padded = np.zeros((self.even_size[1], self.even_size[0], 3), np.uint8)
            padded[: image.shape[0], : image.shape[1]] = image
            image = padded
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="bgr24")
        self.container.mux(self.stream.encode(frame))

    def finish(self) -> None:
        self.container.mux(self.stream.encode(None))  # flush the encoder's delayed frames

    def close(self) -> None:
        self.container.close()

