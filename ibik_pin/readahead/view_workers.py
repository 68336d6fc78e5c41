"""Threads that build one frame's views side by side, in a process that has the cores to itself.

A view's support image and medial axis come from its own silhouette alone, in compiled kernels and
OpenCV calls that release the GIL, so a frame's views can be built at once on several cores: in the
read-ahead's child process (which has the GIL to itself; beside the solver, in a thread, every
handover of the GIL would stall the solve) and in the subject calibration's passes over sampled
frames. Each view is built exactly as one at a time would build it; only the wall time changes.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

__all__ = ["LARGE_VIEW_PIXELS", "built_ahead", "map_views", "read_ahead_workers", "usable_cores"]

#: A view of at least this many pixels is built on threads in the read-ahead's child. Its images
#: then take longer than a frame's solve (four 1088 x 1920 views: 58-73 ms on one thread, the solve
#: 15-17 ms), so the parent waits for the child. Smaller ones are ready before the solve needs them,
#: and more threads would only take the solver's core: on real motion at 640 x 480 the solves went
#: 142 -> 125 frames/s (2 views) and 146 -> 127 (4 views) with them, the frame loop no faster.
LARGE_VIEW_PIXELS = 1_000_000

T = TypeVar("T")
R = TypeVar("R")

# One pool per process: a pool's threads do not survive a fork, so a child makes its own.
_pool: tuple[int, int, ThreadPoolExecutor] | None = None


def usable_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def map_views(build: Callable[[T], R], items: Sequence[T], workers: int) -> list[R]:
    """[build(item) for item in items], in order, on up to `workers` threads (1: in this thread)."""
    global _pool
    workers = max(1, min(int(workers), len(items)))
    if workers == 1:
        return [build(item) for item in items]
    if _pool is None or _pool[0] != os.getpid() or _pool[1] < workers:
        _pool = (os.getpid(), workers, ThreadPoolExecutor(max_workers=workers, thread_name_prefix="ibik-views"))
    return list(_pool[2].map(build, items))


def built_ahead(build: Callable[[T], R], items: Iterable[T]) -> Iterator[R]:
    """build(item) for each item, in order, the next item's built on a thread while the caller works
    on the current one: the subject calibration's passes score a frame in Python while the next
    frame's views are built in compiled kernels that release the GIL. The same values as
    [build(item) for item in items]; an exception in a build is raised where its item is taken."""
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="ibik-ahead") as executor:
        pending = None
        for item in items:
            future = executor.submit(build, item)
            if pending is not None:
                yield pending.result()
            pending = future
        if pending is not None:
            yield pending.result()


def read_ahead_workers(sizes: Sequence[tuple[int, int]]) -> int:
    """Threads for the read-ahead's child to build a frame's views of (width, height) `sizes` [px]:
    the usable cores when every view is large (LARGE_VIEW_PIXELS), else 1."""
    large = bool(sizes) and all(width * height >= LARGE_VIEW_PIXELS for width, height in sizes)
    return usable_cores() if large else 1
