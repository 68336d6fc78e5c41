"""Tests of the progress bar of `ibik track` (tqdm): drawn on a terminal with the count, the rate and
the time left; silent with --quiet and when stderr is not a terminal (a log file, a pipe)."""

from __future__ import annotations

import io
import re
import sys

import pytest

from ibik_pin.app.demo import prepare_demo_inputs
from ibik_pin.cli import main

# tqdm's last drawing of a finished bar: "tracking: 100%|####| 10/10 [00:00<00:00, 22.9frame/s]";
# below 1 frame/s the rate reads "1.23s/frame".
FINISHED_BAR = re.compile(r"tracking: 100%\|.*\| 10/10 \[\d\d:\d\d<\d\d:\d\d, +[\d.]+(frame/s|s/frame)\]")


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


@pytest.fixture(scope="module")
def targets(tmp_path_factory):
    """10 frames of real walking (CMU 35_01 at 5 Hz); only the targets are tracked (no image)."""
    return prepare_demo_inputs(tmp_path_factory.mktemp("walk") / "input", views=1, frame_step=24).targets


def track(targets, out, *extra: str) -> int:
    return main(["track", "--targets", str(targets), "--no-image", "--out", str(out), *extra])


def test_on_a_terminal_the_bar_shows_the_frames_the_rate_and_the_time_left(targets, tmp_path, monkeypatch):
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)

    assert track(targets, tmp_path / "out") == 0

    drawings = [line for line in re.split(r"[\r\n]", terminal.getvalue()) if line.startswith("tracking:")]
    assert drawings, terminal.getvalue()
    assert FINISHED_BAR.search(drawings[-1]), drawings[-1]


def test_quiet_draws_nothing_even_on_a_terminal(targets, tmp_path, monkeypatch, capsys):
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)

    assert track(targets, tmp_path / "out", "--quiet") == 0

    assert terminal.getvalue() == ""
    assert capsys.readouterr().out == ""


def test_a_log_or_a_pipe_gets_no_bar(targets, tmp_path, capsys):
    assert track(targets, tmp_path / "out") == 0

    error = capsys.readouterr().err  # captured stderr is not a terminal
    assert "tracking:" not in error
    assert "%|" not in error
