"""Numba's compilation is measured apart, so that a first run's frame rates can leave it out."""

import time

import numba
import numpy as np

from ibik_pin.tracking.compile_time import CompileTimer
from ibik_pin.tracking.result import TrackingResult


def test_a_kernel_compiled_inside_a_span_is_timed_inside_it_and_a_second_call_compiles_nothing():
    @numba.njit
    def twice(values):  # a new function: compiled on its first call whatever the cache holds
        return values * 2.0

    timer = CompileTimer()
    with timer.recording():
        started = time.perf_counter()
        twice(np.ones(3))
        span = (started, time.perf_counter())
        twice(np.ones(3))
    assert len(timer.intervals) == 1 and 0.0 < timer.seconds <= span[1] - span[0]
    assert np.isclose(timer.seconds_within([span]), timer.seconds)
    assert timer.seconds_within([(span[1], span[1] + 10.0)]) == 0.0


def test_frame_rates_leave_the_compilation_out():
    result = TrackingResult(q=np.zeros((10, 3)), keypoint_names=[], keypoints=np.zeros((10, 0, 3)),
                            target_residuals=np.zeros(10), overlap=np.zeros((10, 0)),
                            solve_seconds=2.0, loop_seconds=3.0, compile_seconds=1.5, solve_compile_seconds=1.0)
    assert result.solve_frames_per_second == 10.0 and result.frames_per_second == 10.0 / 1.5
