"""Each frame's image inputs prepared in a child process, the arrays passed through shared memory.

Why a process and not only a thread: the thread that prepares the images (readahead.frames_ahead)
runs compiled code that releases the GIL, and every time it takes the GIL back the solver's thread
waits for a hand-over. Measured on real boxing with two views, the solver's own work took 39% longer
beside that thread than alone (6.3 against 4.5 ms a frame). A child process has a GIL of its own.

How: the parent prepares frame 0 itself, then forks; the child, a copy of the parent at that point
(the silhouette source with its state, the cameras, nothing pickled), prepares frames 1, 2, ... in
order. Each frame's arrays (support windows; the silhouettes bit-packed with their inside
distances, for a read outside a window; medial axes) are written into one of the slots of an
anonymous shared mapping, and a small message through a pipe says where. The parent reads them in
place and hands the slot back once two more frames have been asked for: a frame's images stay
valid while the next frame is set up. An array that does not fit its slot travels in the message
instead. With up to 32 slots the child gets far ahead while the parent searches the first frame's
pose (on the paper's arm, about 45 frames in the search's 55 ms; frames/s over the frames after
the first went 668 -> 847 against 4 slots, means of nine runs each). Per-frame figures the source
keeps (the silhouette quality report's) come back with each frame.

A child slower than the parent (one view on the paper's arm: 1.1 ms to build a frame's support
against 0.65 ms to solve it, measured over 600 frames) would keep the parent waiting. So the parent,
when no frame is ready, claims the first frame the child cannot have started yet (beyond its slots,
flagged in a shared byte per frame) and prepares it itself; the child skips it. On the arm about a
fifth of the frames were claimed and the frames after the first went from 1.1 to 0.87-0.89 ms
(600 frames). The silhouettes must then be readable in any order (mask files, decoded videos).

The child also runs jobs the parent sends (`submit`): a job reads a frame's images and whatever
the child's copy of the parent's objects holds. The tracker sends it a frame's level outcomes
(tracking.outcomes), about 0.7 ms of work that needs the frame's solution but nothing of the next
frame's solve, when the child is ahead (`child_is_ahead`): with two views it prepares a frame in
less time than the parent solves one, and would otherwise wait; with four it is the slower one,
and the parent keeps the work.

Fork only: on Linux. Elsewhere readahead.frames_ahead uses a thread.
"""

from __future__ import annotations

import collections
import contextlib
import mmap
import multiprocessing
import multiprocessing.connection
import multiprocessing.process
import pickle
import signal
import sys
import warnings
from collections.abc import Callable
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from ibik_pin.exceptions import IbikError
from ibik_pin.readahead.frame_slots import FrameSlots, pack_frame, slot_bytes_for, unpack_frame

__all__ = ["FrameRecords", "ImageProcess", "can_fork"]

# Slots of the shared mapping: the frame being solved and the one before keep theirs (their arrays
# are read in place), the child prepares the next frames in the others, as far ahead as they go: it
# gets ahead while the parent runs the first frame's search (tens of ms), and the lead absorbs the
# two processes' jitter. As many slots as fit SLOT_BUDGET_BYTES, within MIN_SLOTS .. MAX_SLOTS
# (the mapping's pages take memory only once written).
MIN_SLOTS, MAX_SLOTS = 4, 32
SLOT_BUDGET_BYTES = 128 << 20
HELD = 2
# Frames ready beyond the one being solved from which the child counts as ahead (child_is_ahead).
AHEAD = 2
_STOP_WAIT_S = 5.0


def can_fork() -> bool:
    """Whether images can be prepared in a forked process here: on Linux (fork is unsafe on macOS),
    and not from a daemonic process (a pool's worker), which may not have children."""
    return (sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


@runtime_checkable
class FrameRecords(Protocol):
    """A silhouette source that keeps per-frame figures (app.video_inputs.SilhouetteQualityReader):
    the child process reads the frames, so their figures are sent back to the parent's source."""

    def recorded_frames(self) -> int:
        """How many frames, from frame 0 on, hold their figures."""
        ...

    def records(self, start: int, stop: int) -> object:
        """The figures of frames start .. stop - 1 (picklable)."""
        ...

    def add_records(self, start: int, records: object) -> None:
        """Take the figures of frames from `start` on, as `records` gave them (a frame that process
        did not read keeps the figures read here)."""
        ...

    def read_elsewhere(self, frame: int) -> None:
        """Frame `frame` is read by the other process, which keeps its figures: count it as recorded."""
        ...


def _child(prepare: Callable, frame_count: int, connection, slots: FrameSlots, records: FrameRecords | None,
           job: Callable | None, first, claimed) -> None:
    """The child's loop: frames 1 .. frame_count - 1 but those the parent has claimed (`claimed`, a
    shared byte per frame), each into a free slot, and the jobs the parent sends, until the parent
    closes its end; an error is sent at its frame and ends the loop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle; it ends the child
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the parent's handler (the CLI's raises an error)
    # OpenCV's thread pool does not survive a fork (its calls can hang in the child: opencv#5150,
    # opencv-python#249); without threads its functions run in the calling thread.
    cv2.setNumThreads(0)
    warnings.simplefilter("ignore")  # the parent reports what matters; the child writes nothing
    free = list(range(slots.count))
    # The images of the last frames prepared, for the jobs. A job comes for the frame the parent has
    # just solved, t: the parent then holds the slots of t - 1 and t, so the child has sent at most
    # count frames of its own from t - 1 on (the frames the parent claimed take none, and are not
    # prepared here) and prepared one more: t is among the last count + 2 it prepared. Jobs come in
    # order, so the frames up to a job's are dropped with it.
    kept = {0: first} if job is not None else {}
    kept_for_jobs = slots.count + 2

    def handle(message) -> bool:
        """A slot handed back, or a job run and its result sent; False after a failed job."""
        if not isinstance(message, tuple):
            free.append(message)
            return True
        _, frame, payload = message
        try:
            result = job(frame, kept.get(frame), payload)  # type: ignore[misc]
        except BaseException as error:
            connection.send(("error", frame, _picklable(error)))
            return False
        connection.send(("result", frame, result))
        for done in [kept_frame for kept_frame in kept if kept_frame <= frame]:
            del kept[done]
        return True

    sent = records.recorded_frames() if records is not None else 0
    for frame in range(1, frame_count):
        if claimed[frame]:  # the parent prepares it (ImageProcess._claim)
            if records is not None:
                records.read_elsewhere(frame)
            continue
        try:
            images = prepare(frame)
        except BaseException as error:  # every failure goes to the parent, at its frame
            connection.send(("error", frame, _picklable(error)))
            return
        if job is not None:
            kept[frame] = images
            if len(kept) > kept_for_jobs:  # counted, not by frame number: claimed frames are skipped
                del kept[min(kept)]
        while not free:
            if not handle(connection.recv()):
                return
        slot = free.pop()
        description, arrays = pack_frame(images)
        news = None
        if records is not None and records.recorded_frames() > sent:
            stop = records.recorded_frames()
            news = (sent, records.records(sent, stop))
            sent = stop
        connection.send(("frame", frame, slot, description, slots.write(slot, arrays), news))
        while connection.poll():  # jobs sent meanwhile, before the next frame
            if not handle(connection.recv()):
                return
    if job is None:
        return
    while True:  # every frame sent: the jobs left, until the parent closes its end
        try:
            message = connection.recv()
        except (EOFError, OSError):
            return
        if not handle(message):
            return


def _picklable(error: BaseException) -> BaseException:
    try:
        pickle.loads(pickle.dumps(error))
        return error
    except Exception:  # any failure to round-trip
        return IbikError(f"preparing a frame's images failed: {type(error).__name__}: {error}")


class ImageProcess:
    """Frames 0 .. frame_count - 1 of `prepare(frame)` (FrameImages), asked for in order: frame 0
    prepared here, the others in a forked child; the views of later frames get frame 0's camera
    objects. `records`: the source whose per-frame figures the child sends back, or None. `job`:
    job(frame, images, payload) -> result, run in the child for each `submit` (images: that frame's
    FrameImages, or None if the child no longer keeps them); its results are picked up by `results`
    and `finish_jobs`. Call close() when done (also after an error)."""

    def __init__(self, prepare: Callable, frame_count: int, records: FrameRecords | None = None,
                 job: Callable | None = None) -> None:
        self._prepare, self._frame_count = prepare, frame_count
        self._job = job
        self._results: dict[int, object] = {}
        self._outstanding = 0
        self._waiting: collections.deque = collections.deque()  # the child's messages read ahead
        self._cameras: list = []
        self._records = records
        self._next = 0
        self._held: list[int] = []  # the slots of the last frames handed out, oldest first
        self._process: multiprocessing.process.BaseProcess | None = None
        self._connection: multiprocessing.connection.Connection | None = None
        self._memory: mmap.mmap | None = None
        self._slots: FrameSlots | None = None
        self._claimed: np.ndarray | None = None  # per frame, 1 once the parent has claimed it
        self._own: dict[int, object] = {}  # the frames claimed and prepared here (or their errors), until asked for
        self._last_claim = 0

    def get(self, frame: int):
        if frame != self._next:
            raise RuntimeError(f"ImageProcess: frames are prepared in order; asked {frame}, next {self._next}")
        self._next += 1
        if frame == 0:
            first = self._prepare(0)
            self._cameras = [view.camera for view in first.views]
            if self._frame_count > 1:
                self._start(first)
            return first
        if frame in self._own:
            images = self._own.pop(frame)
            if isinstance(images, Exception):  # a claimed frame's failure, raised at its frame
                raise images
            return images
        # Rather than wait for a child that falls behind, prepare a frame it cannot have started (job
        # results that have arrived are no frame: they are read aside first).
        while self._connection is not None:
            self._read_arrived()
            if self._waiting or not self._claim(frame):
                break
        return self._receive(frame)

    def _claim(self, frame: int) -> bool:
        """Claim and prepare here the first frame the child cannot have started, while the parent
        waits for `frame`; False when none is left (or enough are held here already).

        The child holds at most `count` frames in slots, from frame - HELD on (the parent has handed
        back the earlier ones' slots), and prepares one more; claimed frames take no slot: those
        not yet asked for (all beyond `frame`) and at most HELD among the last asked. So the child
        has started nothing past frame + count + len(own). The claim is written before the parent
        hands back another slot (a pipe write), which the child must read before it gets further:
        it then finds the frame claimed.
        """
        assert self._claimed is not None and self._slots is not None
        claim = max(frame + self._slots.count + len(self._own) + 1, self._last_claim + 1)
        if claim >= self._frame_count or len(self._own) >= self._slots.count:
            return False
        self._claimed[claim] = 1
        self._last_claim = claim
        try:
            self._own[claim] = self._prepare(claim)
        except Exception as error:  # raised when the frame is asked for, as the child's errors are
            self._own[claim] = error
        return True

    def _start(self, first) -> None:
        slot_bytes = slot_bytes_for(first)
        count = min(max(SLOT_BUDGET_BYTES // slot_bytes, MIN_SLOTS), MAX_SLOTS, self._frame_count + HELD)
        self._memory = mmap.mmap(-1, count * slot_bytes + self._frame_count)  # anonymous and shared
        self._slots = FrameSlots(self._memory, slot_bytes, count)
        self._claimed = np.frombuffer(self._memory, np.uint8, self._frame_count, count * slot_bytes)
        context = multiprocessing.get_context("fork")
        self._connection, child_end = context.Pipe(duplex=True)
        for stream in (sys.stdout, sys.stderr):  # nothing buffered to be written twice by the child
            stream.flush()
        self._process = context.Process(target=_child, name="ibik-frame-images", daemon=True,
                                        args=(self._prepare, self._frame_count, child_end, self._slots,
                                              self._records, self._job, first, self._claimed))
        self._process.start()
        child_end.close()

    def _next_message(self, waiting_for: str, results_only: bool = False):
        """The child's next message other than a job result (results_only: the next job result),
        job results kept aside; raises the child's error, or an IbikError if it ended."""
        assert self._connection is not None
        while True:
            if self._waiting and not results_only:
                message = self._waiting.popleft()
            else:
                try:
                    message = self._connection.recv()
                except (EOFError, OSError):  # the pipe closed, or reset (a socket pair) by the child's end
                    if self._process is not None:
                        self._process.join(_STOP_WAIT_S)
                    code = self._process.exitcode if self._process is not None else None
                    raise IbikError(f"the process preparing the images ended before {waiting_for} "
                                    f"(exit code {code})") from None
            if message[0] == "error":
                raise message[2]
            if message[0] != "result":
                if results_only:
                    raise RuntimeError(f"ImageProcess: a {message[0]!r} message while finishing the jobs")
                return message
            self._take_result(message)
            if results_only:
                return message

    def _take_result(self, message: tuple) -> None:
        self._results[message[1]] = message[2]
        self._outstanding -= 1

    def _receive(self, frame: int):
        assert self._connection is not None and self._slots is not None
        _, sent_frame, slot, description, places, news = self._next_message(f"frame {frame}")
        if sent_frame != frame:
            raise RuntimeError(f"ImageProcess: received frame {sent_frame}, expected {frame}")
        # The frame's arrays are read in place: its slot goes back to the child once two more frames
        # have been asked for (the tracker's image task holds a frame's views until the next frame's).
        self._held.append(slot)
        if len(self._held) > HELD:
            with contextlib.suppress(OSError):  # the child may have sent its last frame and ended
                self._connection.send(self._held.pop(0))
        arrays = self._slots.read(slot, places)
        if news is not None and self._records is not None:
            self._records.add_records(*news)
        return unpack_frame(description, arrays, self._cameras)

    def child_is_ahead(self) -> bool:
        """Whether the child has AHEAD frames ready beyond the one being solved: it is keeping ahead
        of the parent, and a job sent now costs the parent nothing it would not spend waiting. With
        fewer frames ready the child is keeping pace at best (four large views), and the parent had
        better do the work itself; a lead spent on jobs is thus never spent below AHEAD frames."""
        if self._connection is None:
            return False
        self._read_arrived()
        return sum(message[0] == "frame" for message in self._waiting) >= AHEAD

    def _read_arrived(self) -> None:
        """Read the child's messages that have arrived: job results taken aside, frames and errors
        kept in order for _next_message."""
        assert self._connection is not None
        with contextlib.suppress(EOFError, OSError):  # a child that ended is found out at the next frame
            while self._connection.poll():
                message = self._connection.recv()
                if message[0] == "result":
                    self._take_result(message)
                else:
                    self._waiting.append(message)

    def submit(self, frame: int, payload: object) -> bool:
        """Send `job(frame, images, payload)` to the child; False (nothing sent) without a child or
        a job, or once the child has ended."""
        if self._job is None or self._connection is None or self._process is None:
            return False
        if self._claimed is not None and self._claimed[frame]:  # prepared here: the child lacks its images
            return False
        try:
            self._connection.send(("job", frame, payload))
        except OSError:
            return False
        self._outstanding += 1
        return True

    def results(self) -> dict[int, object]:
        """The job results received so far and not yet taken, by frame."""
        results, self._results = self._results, {}
        return results

    def finish_jobs(self) -> dict[int, object]:
        """Wait for every job submitted; their results not yet taken, by frame."""
        for message in self._waiting:  # a failed job's error, read ahead by child_is_ahead
            if message[0] == "error":
                raise message[2]
        while self._outstanding > 0:
            self._next_message("the results of its last jobs", results_only=True)
        return self.results()

    def close(self) -> None:
        """End the child (at once if frames are left) and free the shared memory."""
        if self._process is not None:
            if self._process.is_alive():
                self._process.terminate()
            self._process.join(_STOP_WAIT_S)
            if self._process.is_alive():
                self._process.kill()
                self._process.join()
            self._process = None
        if self._connection is not None:
            self._connection.close()
            self._connection = None
        self._claimed = None
        self._own.clear()
        if self._memory is not None:
            with contextlib.suppress(BufferError):  # an array still views it: the mapping goes with it
                self._memory.close()
            self._memory = None
