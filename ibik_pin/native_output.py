"""What C libraries print: FFmpeg, libpng and urdfdom write their complaints straight to the
process's stderr, before the one-line error the package raises about the same file. This module
catches those lines so that the error can quote them instead.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass

__all__ = ["NativeOutput", "captured_native_stderr"]


@dataclass
class NativeOutput:
    """The text written to file descriptor 2 inside :func:`captured_native_stderr`."""

    text: str = ""

    def first_line(self) -> str:
        """The first non-empty line, without OpenCV's log prefix ("[ WARN:0@0.01] global "); empty
        when nothing was written."""
        line = next((line.strip() for line in self.text.splitlines() if line.strip()), "")
        return re.sub(r"^\[[^]]*\]\s*(global\s+)?", "", line)


@contextlib.contextmanager
def captured_native_stderr() -> Iterator[NativeOutput]:
    """Send file descriptor 2 to a temporary file for the block's duration; the text is in the
    yielded NativeOutput once the block ends. Python's own sys.stderr is flushed first so that
    nothing of the program's is caught; where fd 2 cannot be duplicated, nothing is captured."""
    output = NativeOutput()
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):
        yield output
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield output
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            output.text = sink.read().decode("utf-8", errors="replace")
