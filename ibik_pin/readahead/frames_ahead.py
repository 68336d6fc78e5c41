"""Each frame's image inputs, prepared ahead while the frame before is solved.

Reading a frame's silhouettes and building its support images and medial axes needs nothing from
the solve. So, by default, a forked child process prepares the next frames while the main process
solves (readahead.image_process); where fork is not available, a worker thread prepares frame
t + 1 while frame t is solved (their heavy parts, compiled, release the GIL, but each hand-over of
the GIL stalls the solver: the process does not share it).

Either way the frames are prepared in order, one at a time, so a silhouette source that remembers
what it read (a temporal filter, the silhouette quality report) sees the same calls as without
them. An error while preparing a frame is raised when the tracker asks for that frame.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from types import TracebackType

from ibik_pin.exceptions import InputError
from ibik_pin.readahead.frame_images import FrameImages
from ibik_pin.readahead.image_process import FrameRecords, ImageProcess, can_fork

__all__ = ["READ_AHEAD_MODES", "FrameImagesAhead"]


READ_AHEAD_MODES = ("process", "thread", "off")


class FrameImagesAhead:
    """Prepares frames 0 .. frame_count - 1 with `prepare(frame)` ahead of the one asked (`prepare`
    None: a run without images, which asks for none).

    Modes: "process" (readahead.image_process: a forked child, a few frames ahead; where fork is
    not available, a thread), "thread" (one frame ahead in a worker thread), "off" (each frame
    when asked, in the caller's thread). The process mode needs the frames asked in order, and a
    frame's arrays are the child's shared memory, valid until two more frames have been asked for;
    `records` is the silhouette source whose per-frame figures the child sends back
    (image_process.FrameRecords), if any. `job(frame, images, payload)`: work that `offload` hands
    to the child process when it is ahead (the caller does it itself otherwise, or in another mode).

    Use as a context manager: leaving it (also by an exception or a signal) cancels the frames
    prepared ahead and waits for one being prepared (a thread), or ends the child process.
    """

    def __init__(self, prepare: Callable[[int], FrameImages] | None, frame_count: int, mode: str = "process",
                 records: FrameRecords | None = None, job: Callable | None = None) -> None:
        if mode not in READ_AHEAD_MODES:
            raise InputError(f"read-ahead mode: expected one of {', '.join(READ_AHEAD_MODES)}, got {mode!r}")
        if mode == "process" and not can_fork():
            mode = "thread"
        self._prepare = prepare
        self._frame_count = frame_count
        self._mode = mode
        self._records = records
        self._job = job
        self._entered = False
        self._executor: ThreadPoolExecutor | None = None
        self._process: ImageProcess | None = None
        self._ahead: dict[int, Future[FrameImages]] = {}

    @property
    def mode(self) -> str:
        """The mode in use: the one asked for, or "thread" for "process" where fork is not available."""
        return self._mode

    def __enter__(self) -> FrameImagesAhead:
        self._entered = True
        if self._prepare is not None and self._mode == "thread":
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ibik-frame-images")
        elif self._prepare is not None and self._mode == "process":
            self._process = ImageProcess(self._prepare, self._frame_count, self._records, self._job)
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        for future in self._ahead.values():
            future.cancel()
        self._ahead.clear()
        self._entered = False
        if self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None
        if self._process is not None:
            self._process.close()
            self._process = None

    def get(self, frame: int) -> FrameImages:
        """Frame `frame`'s images (prepared now if it was not ahead); starts preparing the next one."""
        if not self._entered or self._prepare is None:
            raise RuntimeError("FrameImagesAhead.get outside its `with` block or without `prepare`")
        if self._process is not None:
            return self._process.get(frame)
        if self._executor is None:
            return self._prepare(frame)
        future = self._ahead.pop(frame, None)
        if future is None:
            future = self._executor.submit(self._prepare, frame)
        if frame + 1 < self._frame_count and frame + 1 not in self._ahead:
            self._ahead[frame + 1] = self._executor.submit(self._prepare, frame + 1)
        return future.result()

    def offload(self, frame: int, payload: object) -> bool:
        """Hand job(frame, images, payload) to the child process if it is ahead of the caller; False
        (nothing handed) otherwise: the caller does the work itself. Call after get(frame)."""
        return (self._process is not None and self._process.child_is_ahead()
                and self._process.submit(frame, payload))

    def results(self) -> dict[int, object]:
        """The results of the jobs offloaded so far that have come back and were not yet taken, by frame."""
        return self._process.results() if self._process is not None else {}

    def finish_jobs(self) -> dict[int, object]:
        """Wait for every job offloaded; the results not yet taken, by frame."""
        return self._process.finish_jobs() if self._process is not None else {}
