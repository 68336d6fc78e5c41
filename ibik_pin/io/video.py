"""Video files, read frame by frame with OpenCV: a reader that reports the size and frame rate,
and a generator of frames for a single pass.
"""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import PathLike, as_path
from ibik_pin.native_output import captured_native_stderr

__all__ = ["VideoReader", "read_frames"]


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
        self.path = as_path(path)
        if not self.path.is_file():
            raise FileFormatError(f"video file '{self.path}': expected a readable video, found no such file")
        self._capture: cv2.VideoCapture | None = self._open()
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
        with captured_native_stderr() as decoder:  # FFmpeg's complaints, quoted below
            try:
                capture = cv2.VideoCapture(str(self.path))
            except cv2.error as error:  # pragma: no cover - depends on the OpenCV build
                raise FileFormatError(f"video file '{self.path}': OpenCV cannot open it ({error})") from None
        if not capture.isOpened():
            capture.release()
            said = f" ({decoder.first_line()})" if decoder.first_line() else ""
            raise FileFormatError(f"video file '{self.path}': expected a video OpenCV can decode, found none{said}")
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

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def read_frames(path: PathLike, max_frames: int | None = None) -> Iterator[np.ndarray]:
    """The frames of a video, one at a time, the file closed when the iteration ends.

    Args:
        path: The video file.
        max_frames: Stop after this many frames; None for all.

    Yields:
        Frames (H, W, 3) BGR uint8.

    Raises:
        FileFormatError: The file cannot be opened as a video.
    """
    with VideoReader(path) as reader:
        for index, frame in enumerate(reader):
            if max_frames is not None and index >= max_frames:
                return
            yield frame
