"""A one-line progress bar on a terminal, without dependencies."""

from __future__ import annotations

import numbers
import sys
import time
from collections.abc import Callable
from typing import TextIO

from ibik_pin.exceptions import InputError

__all__ = ["ProgressBar"]

_BAR_WIDTH = 20  # [characters]
_MIN_INTERVAL = 0.1  # [s] between two redraws: at most 10 per second


class ProgressBar:
    """``\\r<description> 37/100 [=======>            ] 12.3 fps ETA 4s`` redrawn on one line.

    It draws only when enabled and the stream is a terminal (so logs and pipes stay clean), at
    most 10 times per second, and ends its line when closed. Use it as a context manager::

        with ProgressBar(len(frames), "tracking", enabled=not quiet) as bar:
            for frame in frames:
                ...
                bar.update()

    Args:
        total: The number of steps expected (>= 0).
        description: The text before the counter.
        enabled: Whether to draw at all (e.g. ``not quiet``).
        stream: Where to draw; default ``sys.stderr`` at construction.
        clock: The time source [s]; default ``time.monotonic``.

    Attributes:
        count: The steps done so far.
        active: Whether the bar draws (enabled and the stream is a terminal).
    """

    def __init__(
        self,
        total: int,
        description: str = "",
        enabled: bool = True,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if isinstance(total, bool) or not isinstance(total, numbers.Integral) or total < 0:
            raise InputError(f"total: expected a non-negative integer, got {total!r}")
        self.total = int(total)
        self.description = description
        self.stream = sys.stderr if stream is None else stream
        self.count = 0
        self.active = bool(enabled) and _is_terminal(self.stream)
        self._clock = clock
        self._start = clock()
        self._last_draw = -float("inf")
        self._drawn_width = 0
        self._closed = False

    def update(self, n: int = 1) -> None:
        """Count `n` more steps done; redraw if the last drawing is 0.1 s old or more."""
        self.count += n
        if not self.active or self._closed:
            return
        now = self._clock()
        if now - self._last_draw >= _MIN_INTERVAL:
            self._draw(now)

    def close(self) -> None:
        """Draw the final state and end the line (once; later calls do nothing)."""
        if self._closed:
            return
        self._closed = True
        if self.active:
            self._draw(self._clock())
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exception_info: object) -> None:
        self.close()

    def text(self, now: float | None = None) -> str:
        """The line as drawn at time `now` [s] of the clock (default: now), without ``\\r``."""
        now = self._clock() if now is None else now
        elapsed = now - self._start
        fraction = min(self.count / self.total, 1.0) if self.total else 1.0
        filled = int(round(_BAR_WIDTH * fraction))
        bar = ("=" * filled + (">" if filled < _BAR_WIDTH else "")).ljust(_BAR_WIDTH)
        parts = [self.description, f"{self.count}/{self.total}", f"[{bar}]"]
        if elapsed > 0.0 and self.count > 0:
            rate = self.count / elapsed
            parts.append(f"{rate:.1f} fps")
            if self.count < self.total:
                parts.append(f"ETA {_duration((self.total - self.count) / rate)}")
        return " ".join(part for part in parts if part)

    def _draw(self, now: float) -> None:
        line = self.text(now)
        # Blanks clear what a longer previous line left behind.
        self.stream.write("\r" + line.ljust(self._drawn_width))
        self.stream.flush()
        self._drawn_width = len(line)
        self._last_draw = now


def _is_terminal(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def _duration(seconds: float) -> str:
    """``4s``, ``2m05s`` or ``1h02m``."""
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
