"""Tests of ibik_pin.progress: what the bar draws, when, and when it stays silent."""

import io

import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.progress import ProgressBar


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


class Clock:
    """A clock [s] the test moves by hand."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_the_line_shows_the_count_the_bar_the_rate_and_the_time_left():
    clock = Clock()
    bar = ProgressBar(100, "tracking", stream=Terminal(), clock=clock)
    bar.count = 37
    clock.now = 3.0

    assert bar.text() == "tracking 37/100 [=======>            ] 12.3 fps ETA 5s"


def test_the_time_left_is_written_in_minutes_beyond_a_minute():
    clock = Clock()
    bar = ProgressBar(1000, "solving", stream=Terminal(), clock=clock)
    bar.count = 10
    clock.now = 1.25

    assert bar.text().endswith("8.0 fps ETA 2m04s")


def test_updates_redraw_at_most_ten_times_per_second_and_closing_ends_the_line():
    clock, stream = Clock(), Terminal()

    with ProgressBar(1000, "frames", stream=stream, clock=clock) as bar:
        for _ in range(1000):
            clock.now += 0.001  # 1000 updates in 1 s
            bar.update()

    output = stream.getvalue()
    assert 10 <= output.count("\r") <= 12  # ~10 redraws in 1 s, and the final one
    assert output.endswith("\n")
    assert output.rstrip("\n").split("\r")[-1].startswith("frames 1000/1000 [====================]")
    assert "ETA" not in output.split("\r")[-1]


def test_a_shorter_line_is_padded_to_clear_the_previous_one():
    clock, stream = Clock(), Terminal()
    bar = ProgressBar(10, "x", stream=stream, clock=clock)
    clock.now = 1.0
    bar.update()
    first = stream.getvalue().split("\r")[-1]
    clock.now = 1000.0
    bar.update(9)

    second = stream.getvalue().split("\r")[-1]
    assert len(second) >= len(first)


def test_nothing_is_written_when_disabled_or_when_the_stream_is_not_a_terminal():
    terminal, pipe = Terminal(), io.StringIO()

    with ProgressBar(5, "a", enabled=False, stream=terminal) as disabled:
        disabled.update(5)
    with ProgressBar(5, "b", stream=pipe) as not_a_terminal:
        not_a_terminal.update(5)

    assert terminal.getvalue() == ""
    assert pipe.getvalue() == ""
    assert disabled.count == not_a_terminal.count == 5


def test_the_line_is_ended_even_when_the_work_fails():
    stream = Terminal()

    with pytest.raises(RuntimeError):
        with ProgressBar(5, "failing", stream=stream):
            raise RuntimeError("solver failed")

    assert stream.getvalue().endswith("\n")


def test_the_default_stream_is_standard_error(capsys):
    with ProgressBar(3, "quiet") as bar:
        bar.update(3)

    assert capsys.readouterr().err == ""  # captured stderr is not a terminal
    assert not bar.active


@pytest.mark.parametrize("total", [-1, 2.5, "10", True])
def test_a_total_that_is_not_a_non_negative_integer_is_refused(total):
    with pytest.raises(InputError, match="total: expected a non-negative integer"):
        ProgressBar(total)
