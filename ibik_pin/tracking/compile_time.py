"""How much of a run was Numba compiling its kernels, so that a first run's frame rates can be given
without it.

The compiled kernels (solvers, image criteria) are built on their first call and cached on disk: a
first run on a machine spends seconds compiling inside its first frames' solves, later runs none.
Numba announces each compilation as "numba:compile" events; their union over time, and its part
inside given intervals (the solves), is what this measures. Only this process's compilations are
seen: a read-ahead child process compiles its own image kernels unseen.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

from numba.core import event

__all__ = ["CompileTimer"]


class CompileTimer:
    """Records the intervals during which this process compiled, while `recording()` is active.

    Attributes:
        intervals: (start, end) [s, time.perf_counter's clock] of every outermost compilation.
    """

    def __init__(self) -> None:
        self.intervals: list[tuple[float, float]] = []

    @contextlib.contextmanager
    def recording(self) -> Iterator[None]:
        # Numba stamps its events with time.time(); the intervals are kept on perf_counter's clock.
        offset = time.perf_counter() - time.time()
        with event.install_recorder("numba:compile") as recorder:
            yield
        # Nested compilations (a kernel's callees) lie inside their caller's: keep the outermost.
        depth, start = 0, 0.0
        for timestamp, item in recorder.buffer:
            if item.is_start:
                if depth == 0:
                    start = timestamp + offset
                depth += 1
            elif depth > 0:
                depth -= 1
                if depth == 0:
                    self.intervals.append((start, timestamp + offset))

    @property
    def seconds(self) -> float:
        """Total time spent compiling [s]."""
        return sum(end - start for start, end in self.intervals)

    def seconds_within(self, spans: list[tuple[float, float]]) -> float:
        """Time spent compiling inside the given (start, end) spans [s] (spans do not overlap)."""
        return sum(max(0.0, min(end, span_end) - max(start, span_start))
                   for start, end in self.intervals for span_start, span_end in spans)
