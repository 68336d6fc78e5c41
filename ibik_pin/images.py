"""Images: silhouettes, support images (signed distance) and their interpolation, masks and videos.

A support image I_c holds, for one view, how much a projected skeleton sample is rewarded at
each pixel [support units; px for a distance]. The image criterion reads it at projected points
with bilinear interpolation and follows the exact derivative of that interpolant.

Pixel convention (OpenCV's, as in :mod:`ibik_pin.cameras`): the centre of pixel (row i,
column j) is at ``u = j, v = i``.
"""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, NamedTuple, Sequence, Union

import cv2
import numpy as np

from ibik_pin.exceptions import EmptySilhouetteWarning, FileFormatError, InputError

__all__ = [
    "IMAGE_SUFFIXES",
    "SupportImage",
    "SupportSample",
    "TemporalMajority",
    "VideoReader",
    "list_mask_files",
    "obstacle_support",
    "read_mask",
    "silhouettes_from_video",
    "support_from_mask",
]

PathLike = Union[str, os.PathLike]

IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"})


class SupportSample(NamedTuple):
    """A support image read at points.

    Attributes:
        values: (N,) interpolated support [support units].
        gradient: (N, 2) derivative of ``values`` with respect to (u, v) [support units/px].
    """

    values: np.ndarray
    gradient: np.ndarray


def _as_pixels(pixels) -> np.ndarray:
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim != 2 or pixels.shape[1] != 2:
        raise InputError(f"pixels: expected an array of shape (N, 2) [px], found shape {pixels.shape}")
    nan_rows = np.isnan(pixels).any(axis=1)
    if nan_rows.any():  # infinite coordinates are fine: clamped to the border
        raise InputError(f"pixels: expected coordinates that are not NaN, found {int(nan_rows.sum())} row(s) with NaN")
    return pixels


@dataclass(frozen=True, eq=False)
class SupportImage:
    """A support image of one view and whether the image term uses it.

    Attributes:
        values: (H, W) float32 support [support units], read-only.
        enabled: False when the view has no usable silhouette (empty mask): the image term
            skips the view.
    """

    values: np.ndarray
    enabled: bool = True

    def __post_init__(self) -> None:
        values = np.asarray(self.values)
        if values.ndim != 2 or values.shape[0] < 1 or values.shape[1] < 1:
            raise InputError(f"values: expected a non-empty (H, W) array, found shape {values.shape}")
        if not np.issubdtype(values.dtype, np.number) or np.issubdtype(values.dtype, np.complexfloating):
            raise InputError(f"values: expected real numbers, found dtype {values.dtype}")
        values = np.array(values, dtype=np.float32, order="C", copy=True)
        if not np.all(np.isfinite(values)):
            raise InputError("values: expected finite support values, found NaN or infinity")
        values.setflags(write=False)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "enabled", bool(self.enabled))

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) [px]."""
        return self.values.shape[1], self.values.shape[0]

    def __add__(self, other: "SupportImage") -> "SupportImage":
        """Pixel-wise sum, e.g. a silhouette support plus an :func:`obstacle_support`.

        The sum is enabled only if both terms are: a view disabled for an empty silhouette
        stays disabled.
        """
        if not isinstance(other, SupportImage):
            return NotImplemented
        if other.values.shape != self.values.shape:
            raise InputError(
                f"other: expected a support image of size (w, h) = {self.size}, found {other.size}"
            )
        return SupportImage(self.values + other.values, self.enabled and other.enabled)

    def sample_mask(self, pixels: np.ndarray) -> np.ndarray:
        """(N,) True for pixels (N, 2) [px] inside the image (0 <= u <= W - 1, 0 <= v <= H - 1)."""
        pixels = _as_pixels(pixels)
        height, width = self.values.shape
        u, v = pixels[:, 0], pixels[:, 1]
        return (u >= 0.0) & (u <= width - 1) & (v >= 0.0) & (v <= height - 1)

    def sample(self, pixels: np.ndarray) -> SupportSample:
        """Bilinear interpolation of the support and its exact derivative at pixels.

        The gradient is the derivative of the same piecewise-bilinear interpolant, so it agrees
        with finite differences to rounding inside each pixel cell. Outside the image
        (infinity included) the coordinates are clamped to the border and the gradient along a
        clamped axis is zero.

        Args:
            pixels: (N, 2) image coordinates (u, v) [px].

        Returns:
            :class:`SupportSample` with values (N,) and gradient (N, 2) d values / d (u, v).
        """
        pixels = _as_pixels(pixels)
        height, width = self.values.shape
        u = np.clip(pixels[:, 0], 0.0, width - 1)
        v = np.clip(pixels[:, 1], 0.0, height - 1)
        # Cell corner (column0, row0); on the last column/row use the cell to its left/above,
        # so that u = W - 1 interpolates with weight 1 on the last pixel.
        column0 = np.minimum(u.astype(np.intp), max(width - 2, 0))
        row0 = np.minimum(v.astype(np.intp), max(height - 2, 0))
        column1 = np.minimum(column0 + 1, width - 1)
        row1 = np.minimum(row0 + 1, height - 1)
        fraction_u = u - column0
        fraction_v = v - row0
        flat = self.values.ravel()
        top_left = flat[row0 * width + column0].astype(np.float64)
        top_right = flat[row0 * width + column1].astype(np.float64)
        bottom_left = flat[row1 * width + column0].astype(np.float64)
        bottom_right = flat[row1 * width + column1].astype(np.float64)
        top = top_left + fraction_u * (top_right - top_left)
        bottom = bottom_left + fraction_u * (bottom_right - bottom_left)
        values = top + fraction_v * (bottom - top)
        gradient = np.empty((pixels.shape[0], 2))
        gradient[:, 0] = (1.0 - fraction_v) * (top_right - top_left) + fraction_v * (bottom_right - bottom_left)
        gradient[:, 1] = bottom - top
        gradient[:, 0] *= (pixels[:, 0] >= 0.0) & (pixels[:, 0] <= width - 1)
        gradient[:, 1] *= (pixels[:, 1] >= 0.0) & (pixels[:, 1] <= height - 1)
        return SupportSample(values, gradient)


def _as_mask(mask, name: str = "mask") -> np.ndarray:
    """A (H, W) bool array from a bool or uint8 mask (non-zero = set), else InputError."""
    if not isinstance(mask, np.ndarray):
        raise InputError(f"{name}: expected a numpy array of dtype bool or uint8, found {type(mask).__name__}")
    if mask.dtype not in (np.bool_, np.uint8):
        raise InputError(f"{name}: expected dtype bool or uint8 (non-zero = set), found dtype {mask.dtype}")
    if mask.ndim != 2 or mask.shape[0] < 1 or mask.shape[1] < 1:
        raise InputError(f"{name}: expected a 2D (H, W) array, found shape {mask.shape}")
    return mask != 0


def _positive_or_none(value, name: str) -> float | None:
    if value is None:
        return None
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise InputError(f"{name}: expected a positive number of pixels or None, found {value}")
    return value


def _signed_distance(mask: np.ndarray) -> np.ndarray:
    """(H, W) float32 signed Euclidean distance [px] to the mask's border, positive inside.

    The border is taken halfway between a set and an unset pixel, hence the 0.5 shifts: the
    distance then grows by 1 px per pixel across the border as well. The image edge is no
    border (a body cut by the frame continues outside it). Needs both set and unset pixels.
    """
    mask_u8 = mask.astype(np.uint8)
    try:
        inside = cv2.distanceTransform(mask_u8, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        outside = cv2.distanceTransform(1 - mask_u8, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    except cv2.error as error:  # pragma: no cover - OpenCV rejects only malformed input, checked above
        raise InputError(f"mask: OpenCV's distance transform failed: {error}") from None
    return np.where(mask, inside - 0.5, 0.5 - outside).astype(np.float32)


def _smooth(values: np.ndarray, sigma_px: float) -> np.ndarray:
    if sigma_px == 0.0:
        return values
    return cv2.GaussianBlur(values, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REPLICATE)


def support_from_mask(
    mask: np.ndarray,
    inside_cap_px: float | None = 6.0,
    outside_cap_px: float | None = None,
    smooth_sigma_px: float = 1.0,
) -> SupportImage:
    """The signed-distance support of a silhouette.

    Inside the silhouette: the distance to its border, capped at ``inside_cap_px`` (about a
    limb's half-width: the uncapped distance peaks in the trunk and pulls limb segments through
    it). Outside: minus the distance to the body (optionally truncated at ``outside_cap_px``),
    so that a segment lying outside is pulled in. Then a light Gaussian blur.

    Args:
        mask: (H, W) bool or uint8 silhouette, non-zero = person.
        inside_cap_px: cap of the inside distance [px]; None for no cap.
        outside_cap_px: truncation of the outside distance [px]; None for none.
        smooth_sigma_px: standard deviation of the Gaussian blur [px]; 0 for none.

    Returns:
        The support [px]. An empty mask gives zeros with ``enabled=False`` and an
        :class:`EmptySilhouetteWarning`.

    Raises:
        InputError: the mask is not a 2D bool/uint8 array, or a parameter is out of range.
    """
    mask = _as_mask(mask)
    inside_cap_px = _positive_or_none(inside_cap_px, "inside_cap_px")
    outside_cap_px = _positive_or_none(outside_cap_px, "outside_cap_px")
    smooth_sigma_px = float(smooth_sigma_px)
    if not np.isfinite(smooth_sigma_px) or smooth_sigma_px < 0.0:
        raise InputError(f"smooth_sigma_px: expected a non-negative number of pixels, found {smooth_sigma_px}")
    if not mask.any():
        warnings.warn(
            f"mask: the silhouette of size (w, h) = {(mask.shape[1], mask.shape[0])} is empty; "
            "the image term is disabled for this view",
            EmptySilhouetteWarning,
            stacklevel=2,
        )
        return SupportImage(np.zeros(mask.shape, np.float32), enabled=False)
    if mask.all():
        # No border in the image: every pixel is deep inside.
        inside_value = inside_cap_px if inside_cap_px is not None else float(max(mask.shape))
        return SupportImage(np.full(mask.shape, inside_value, np.float32))
    values = _signed_distance(mask)
    if inside_cap_px is not None:
        np.minimum(values, inside_cap_px, out=values)
    if outside_cap_px is not None:
        np.maximum(values, -outside_cap_px, out=values)
    return SupportImage(_smooth(values, smooth_sigma_px))


def obstacle_support(object_mask: np.ndarray, influence_px: float) -> SupportImage:
    """A repulsive support around an object drawn into the image (the paper's Figure 8).

    With s the signed distance to the object's border [px] (positive outside, L = influence_px):
    0 for s >= L, ``-L (1 - s/L)^2`` for 0 <= s < L (smooth at s = L, slope 2 at the border) and
    ``-L + 2 s`` inside (s < 0: keeps decreasing toward the object's middle, so a sample inside
    is pushed out). Add it to a silhouette support with ``+``; scale ``influence_px`` to make
    the obstacle weigh more or less against the silhouette.

    Args:
        object_mask: (H, W) bool or uint8, non-zero = object.
        influence_px: distance over which the object repels [px].

    Returns:
        The support [px], all zeros (and enabled) if the object mask is empty.

    Raises:
        InputError: the mask is not a 2D bool/uint8 array, or ``influence_px`` is not positive.
    """
    mask = _as_mask(object_mask, "object_mask")
    influence = _positive_or_none(influence_px, "influence_px")
    if influence is None:
        raise InputError("influence_px: expected a positive number of pixels, found None")
    if not mask.any():
        return SupportImage(np.zeros(mask.shape, np.float32))
    if mask.all():
        return SupportImage(np.full(mask.shape, -influence - float(max(mask.shape)), np.float32))
    distance = -_signed_distance(mask).astype(np.float64)  # positive outside the object
    ramp = 1.0 - np.clip(distance, 0.0, influence) / influence
    values = np.where(distance >= 0.0, -influence * ramp * ramp, -influence + 2.0 * distance)
    return SupportImage(values)


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
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) if path.is_file() else None
    if image is None:
        reason = "file not found" if not path.exists() else "OpenCV cannot decode it as an image"
        raise FileFormatError(f"mask file '{path}': expected a readable image, found {reason}")
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


class TemporalMajority:
    """Silhouettes with single-frame flicker voted away: each pixel of a camera's mask at frame t
    is the majority over frames t - radius .. t + radius (the first and last frames repeated at
    the ends of the sequence).

    Segmentation errors that last one or two frames (a hole, a passing shadow, a forearm lost
    against the background) are outvoted by the frames around them; a limb moves a few pixels at
    most between neighbouring frames at 50-120 Hz, so clean masks change little. Masks are read
    once each, in frame order, and only the 2 * radius + 1 frames of the window are kept.

    Args:
        source: frame index -> one (H, W) bool mask per camera.
        frame_count: number of frames of the sequence.
        radius: half window [frames], >= 1.
    """

    def __init__(self, source: Callable[[int], Sequence[np.ndarray]], frame_count: int, radius: int = 1) -> None:
        if isinstance(radius, bool) or int(radius) != radius or radius < 1:
            raise InputError(f"radius: expected a whole number of frames >= 1, got {radius!r}")
        if int(frame_count) != frame_count or frame_count < 1:
            raise InputError(f"frame_count: expected a positive whole number, got {frame_count!r}")
        self.source = source
        self.frame_count = int(frame_count)
        self.radius = int(radius)
        self._window: dict[int, list[np.ndarray]] = {}

    def __call__(self, frame: int) -> list[np.ndarray]:
        # The ends repeat the first and last frames (as a median filter's edge replication).
        indices = [min(max(index, 0), self.frame_count - 1)
                   for index in range(frame - self.radius, frame + self.radius + 1)]
        for old in [index for index in self._window if index not in indices]:
            del self._window[old]
        for index in indices:
            if index not in self._window:
                self._window[index] = [_as_mask(mask) for mask in self.source(index)]
        window = [self._window[index] for index in indices]
        return [2 * np.sum([masks[camera] for masks in window], axis=0, dtype=np.int32) > len(window)
                for camera in range(len(window[0]))]


class VideoReader:
    """Frames of a video file, read with OpenCV.

    Each iteration starts again from the first frame. Use as a context manager, or call
    :meth:`close`.

    Attributes:
        path: the video file.
        frame_count: number of frames the container announces (may be approximate for some
            codecs; iteration reads until the end).
        size: (width, height) [px].
        fps: frames per second announced by the container.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileFormatError(f"video file '{self.path}': expected a readable video, found no such file")
        self._capture = self._open()
        self.frame_count = int(self._capture.get(cv2.CAP_PROP_FRAME_COUNT))
        self.size = (
            int(self._capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
            int(self._capture.get(cv2.CAP_PROP_FRAME_HEIGHT)),
        )
        self.fps = float(self._capture.get(cv2.CAP_PROP_FPS))
        if self.size[0] <= 0 or self.size[1] <= 0:
            self.close()
            raise FileFormatError(f"video file '{self.path}': expected a video stream, found frame size {self.size}")

    def _open(self) -> cv2.VideoCapture:
        try:
            capture = cv2.VideoCapture(str(self.path))
        except cv2.error as error:  # pragma: no cover - depends on the OpenCV build
            raise FileFormatError(f"video file '{self.path}': OpenCV cannot open it ({error})") from None
        if not capture.isOpened():
            capture.release()
            raise FileFormatError(f"video file '{self.path}': expected a video OpenCV can decode, found none")
        return capture

    def __iter__(self) -> Iterator[np.ndarray]:
        """Frames (H, W, 3) BGR uint8, from the first one."""
        if self._capture is None:
            raise InputError(f"video file '{self.path}': the reader is closed")
        if self._capture.get(cv2.CAP_PROP_POS_FRAMES) != 0:
            self._capture.release()
            self._capture = self._open()
        while True:
            ok, frame = self._capture.read()
            if not ok:
                return
            yield frame

    def close(self) -> None:
        """Release the video file."""
        if self._capture is not None:
            self._capture.release()
            self._capture = None

    def __enter__(self) -> "VideoReader":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def _frames(path: Path, max_frames: int | None) -> Iterator[np.ndarray]:
    with VideoReader(path) as reader:
        for index, frame in enumerate(reader):
            if max_frames is not None and index >= max_frames:
                return
            yield frame


def _background_frames(paths: Sequence[PathLike], size: tuple[int, int]) -> Iterator[np.ndarray]:
    """Frames of background images and videos, each checked against the video size (w, h)."""
    for path in map(Path, paths):
        if path.suffix.lower() in IMAGE_SUFFIXES:
            image = cv2.imread(str(path), cv2.IMREAD_COLOR) if path.is_file() else None
            if image is None:
                raise FileFormatError(f"background file '{path}': expected a readable image, found none")
            frames: Iterator[np.ndarray] = iter([image])
        else:
            frames = _frames(path, None)
        for frame in frames:
            found = (frame.shape[1], frame.shape[0])
            if found != size:
                raise InputError(
                    f"background file '{path}': expected the video's size (w, h) = {size}, found (w, h) = {found}"
                )
            yield frame


def _keep_largest_components(mask: np.ndarray, max_components: int, min_component_fraction: float) -> np.ndarray:
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if count <= 1:
        return mask.astype(bool)
    areas = stats[1:, cv2.CC_STAT_AREA]
    order = np.argsort(areas)[::-1][:max_components]
    order = order[areas[order] >= min_component_fraction * areas[order[0]]]
    keep = np.zeros(count, bool)
    keep[order + 1] = True
    return keep[labels]


def silhouettes_from_video(
    video_path: PathLike,
    background_paths: Sequence[PathLike] | None = None,
    *,
    max_frames: int | None = None,
    var_threshold: float = 16.0,
    median_frames: int = 31,
    foreground_threshold: int = 30,
    open_px: int = 3,
    close_px: int = 7,
    max_components: int = 3,
    min_component_fraction: float = 0.1,
) -> list[np.ndarray]:
    """Silhouettes of the moving person in a video, by OpenCV background subtraction (MOG2).

    With ``background_paths`` (images or videos of the empty scene, same size as the video),
    MOG2 learns the background on them, then is frozen while the video is segmented. Without,
    it learns on the video itself: the per-pixel temporal median of ``median_frames`` evenly
    spaced frames gives a background plate; MOG2 learns on these frames with the pixels far
    from the plate (``foreground_threshold`` grey levels in some channel) replaced by the
    plate, so that the person does not enter the model while MOG2 learns the noise of the real
    background. Shadows
    (MOG2's shadow label) count as background. Each mask is then cleaned by a morphological
    opening (``open_px``) and closing (``close_px``), and only the ``max_components`` largest
    connected components at least ``min_component_fraction`` of the largest are kept.

    Limits: the camera must be still and the lighting constant. Without a background, a part
    of the body that stays still over more than half of the frames is background (as in the
    Pose2Sim balancing demo, where the trunk barely moves); pass real background frames then.
    Parts whose colour matches the background behind them are lost; a second person or a
    moving object is kept if large enough. The video is decoded twice; besides the masks, only
    the median sample (``median_frames`` frames) is held in memory.

    Args:
        video_path: the video.
        background_paths: images or videos of the empty scene, or None.
        max_frames: segment only the first frames, or None for all.
        var_threshold: MOG2's squared Mahalanobis distance threshold.
        median_frames: number of frames in the median background plate (no background given).
        foreground_threshold: grey-level distance to the plate above which a pixel is kept out
            of MOG2's learning (no background given).
        open_px: diameter of the opening kernel [px]; 0 for none.
        close_px: diameter of the closing kernel [px]; 0 for none.
        max_components: number of connected components kept (the largest).
        min_component_fraction: smallest kept component, as a fraction of the largest's area.

    Returns:
        One (H, W) bool mask per frame, True = person.

    Raises:
        FileFormatError: the video or a background file cannot be read.
        InputError: a background has another size than the video, or a parameter is out of range.
    """
    video_path = Path(video_path)
    for name, value, smallest in (
        ("open_px", open_px, 0),
        ("close_px", close_px, 0),
        ("max_components", max_components, 1),
        ("median_frames", median_frames, 1),
        ("foreground_threshold", foreground_threshold, 0),
    ):
        if int(value) != value or value < smallest:
            raise InputError(f"{name}: expected an integer >= {smallest}, found {value!r}")
    if max_frames is not None and (int(max_frames) != max_frames or max_frames < 1):
        raise InputError(f"max_frames: expected a positive integer or None, found {max_frames!r}")
    if not 0.0 <= min_component_fraction <= 1.0:
        raise InputError(f"min_component_fraction: expected a number in [0, 1], found {min_component_fraction!r}")
    if not var_threshold > 0.0:
        raise InputError(f"var_threshold: expected a positive number, found {var_threshold!r}")

    with VideoReader(video_path) as reader:
        size, frame_total = reader.size, reader.frame_count
    if max_frames is not None:
        frame_total = min(frame_total, max_frames) if frame_total > 0 else max_frames
    subtractor = cv2.createBackgroundSubtractorMOG2(varThreshold=float(var_threshold), detectShadows=True)
    if background_paths:
        for frame in _background_frames(background_paths, size):
            subtractor.apply(frame, learningRate=-1)
    else:
        # Without an announced frame count, the plate is the median of the first frames.
        stride = max(1, -(-frame_total // median_frames)) if frame_total > 0 else 1
        sample = []
        for index, frame in enumerate(_frames(video_path, max_frames)):
            if index % stride == 0:
                sample.append(frame)
                if len(sample) == median_frames:
                    break
        if not sample:
            raise FileFormatError(f"video file '{video_path}': expected frames, found none")
        plate = np.median(np.stack(sample), axis=0).astype(np.uint8)
        for frame in sample:
            channels = cv2.split(cv2.absdiff(frame, plate))
            away = cv2.max(cv2.max(channels[0], channels[1]), channels[2]) > foreground_threshold
            np.copyto(frame, plate, where=away[:, :, np.newaxis])
            subtractor.apply(frame, learningRate=1.0 / len(sample))

    open_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (open_px, open_px)) if open_px > 0 else None
    close_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (close_px, close_px)) if close_px > 0 else None
    masks = []
    for frame in _frames(video_path, max_frames):
        mask = (subtractor.apply(frame, learningRate=0.0) == 255).astype(np.uint8)  # 127 = shadow
        if open_kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, open_kernel)
        if close_kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, close_kernel)
        masks.append(_keep_largest_components(mask, int(max_components), float(min_component_fraction)))
    if not masks:
        raise FileFormatError(f"video file '{video_path}': expected frames, found none")
    return masks
