"""The process app.video_people starts to detect some views' people:
`python -m ibik_pin.app.people_worker FD`.

It reads its job, a pickled list of (view, video) and the DetectionSettings, on its standard input,
and writes pickled messages on the pipe FD, each preceded by its length: ("frames", count) as it
goes, ("done", view, ViewPeople, decode seconds, detection seconds) per view, ("error", text).

A plain interpreter running this module, not a multiprocessing child: a spawned child first
re-runs the parent's main script (the `ibik` command imports its whole CLI there, about a second of
a core per worker on the 2-core machine of docs/method.md) and fails outright under a script that
has no `if __name__ == "__main__":` guard; each video is decoded in its own worker, so frames never
cross a process boundary.
"""

from __future__ import annotations

import os
import pickle
import signal
import struct
import sys
import time
import types
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ibik_pin.exceptions import IbikError
from ibik_pin.io.video import read_frames
from ibik_pin.vision.people import DetectionSettings, ViewPeople, detect_people

__all__ = ["detect_one", "read_message", "write_message"]

_LENGTH = struct.Struct("<Q")


def write_message(stream: BinaryIO, message: tuple) -> None:
    """One pickled message on `stream`, its length first."""
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_LENGTH.pack(len(data)) + data)
    stream.flush()


def read_message(stream: BinaryIO) -> tuple | None:
    """The next message written by write_message, or None at the end of the stream."""
    header = stream.read(_LENGTH.size)
    if len(header) < _LENGTH.size:
        return None
    (length,) = _LENGTH.unpack(header)
    data = stream.read(length)
    if len(data) < length:
        return None
    message = pickle.loads(data)  # written by this package's own worker, through a private pipe
    return message if isinstance(message, tuple) else None


def _timed(frames: Iterator[np.ndarray], spent: list[float]) -> Iterator[np.ndarray]:
    """The frames, the time spent decoding them added to spent[0]."""
    while True:
        start = time.perf_counter()
        try:
            frame = next(frames)
        except StopIteration:
            spent[0] += time.perf_counter() - start
            return
        spent[0] += time.perf_counter() - start
        yield frame


def detect_one(path: Path, settings: DetectionSettings, tick: Callable[[int], object] | None
               ) -> tuple[ViewPeople, float, float]:
    """One view's people, its decode seconds and its detection seconds."""
    decode = [0.0]
    start = time.perf_counter()
    people = detect_people(_timed(read_frames(path), decode), settings, progress=tick)
    return people, decode[0], time.perf_counter() - start - decode[0]


def _serve(jobs: list[tuple[int, Path]], settings: DetectionSettings, messages: BinaryIO) -> None:
    try:
        for view, path in jobs:
            people, decode, detection = detect_one(path, settings, lambda count: write_message(messages,
                                                                                               ("frames", count)))
            write_message(messages, ("done", view, people, decode, detection))
    except IbikError as error:
        write_message(messages, ("error", str(error)))
    except Exception as error:  # the parent re-raises it as the package's error
        write_message(messages, ("error", f"{type(error).__name__}: {error}"))


def _without_pyplot() -> None:
    """Empty stand-ins in the place of matplotlib and its pyplot, which MediaPipe's package imports
    for its drawing helpers: this process never draws. Importing MediaPipe took 1.3 s of a core with
    them and 0.5 s without (measured on the 2-core machine), per worker. Only in this worker
    process, and only where nothing imported matplotlib before."""
    if "matplotlib" not in sys.modules:
        for name in ("matplotlib", "matplotlib.pyplot"):
            sys.modules[name] = types.ModuleType(name)


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to report; it ends this process
    _without_pyplot()
    jobs, settings = pickle.load(sys.stdin.buffer)  # from the parent process, through a private pipe
    with os.fdopen(int(sys.argv[1]), "wb") as pipe:
        _serve(jobs, settings, pipe)
