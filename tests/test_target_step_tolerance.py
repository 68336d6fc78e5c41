"""TrackingSettings.target_step_tolerance on real walking: the targets-only steps of a frame end once
converged, and the motion stays where every step leaves it."""

import numpy as np
import pytest

from ibik_pin.evaluation import ESTIMATED
from ibik_pin.exceptions import InputError
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.tracker import Tracker
from tests.walking_clip import walking_clip


@pytest.fixture(scope="module")
def walking():
    """The rendered walking with 2 views, and the mocap's elbows and knees."""
    return walking_clip(2)


def _track(walking, tolerance):
    """The tracker's motion, and the steps of each targets-only solve (the solves not stopped at
    the criterion's peak with the settings' target_iterations)."""
    body, cameras, masks, names, targets, _ = walking
    tracker = Tracker(body, cameras, TrackingSettings(read_ahead="off", target_step_tolerance=tolerance))
    steps, solve = [], tracker.solver.solve

    def counted(configuration, levels, iterations=15, tolerance=None, stop_at_peak=False):
        result = solve(configuration, levels, iterations=iterations, tolerance=tolerance, stop_at_peak=stop_at_peak)
        if iterations == tracker.settings.target_iterations and not stop_at_peak:
            steps.append(result.iterations)
        return result

    tracker.solver.solve = counted  # type: ignore[method-assign]
    return tracker.track(names, targets, silhouettes=lambda frame: masks[frame]), steps


def test_a_target_step_tolerance_stops_converged_target_steps_and_keeps_the_motion(walking):
    """0.02 rad (the default) against every step: fewer targets-only steps; every elbow and knee within 10 mm of where
    every step puts it, 1 mm on average; their error to the mocap within 0.2 mm; the targets' worst
    distance within 0.1 mm (measured: 5.0 mm at worst, 0.21 mm on average, errors 6.97 and 6.98 mm)."""
    full, full_steps = _track(walking, None)
    early, early_steps = _track(walking, 0.02)
    assert set(full_steps) == {5}
    assert sum(early_steps) < sum(full_steps) and all(1 <= steps <= 5 for steps in early_steps)
    joints = [full.keypoint_names.index(name) for name in ESTIMATED]
    moved = np.linalg.norm(full.keypoints[:, joints] - early.keypoints[:, joints], axis=2)
    assert moved.max() < 0.010 and moved.mean() < 0.001, (moved.max(), moved.mean())
    truth = walking[5]
    errors = [np.mean(np.linalg.norm(result.keypoints[:, joints] - truth, axis=2)) for result in (full, early)]
    assert abs(errors[0] - errors[1]) < 2e-4, errors
    assert abs(np.nanmax(full.target_distances) - np.nanmax(early.target_distances)) < 1e-4


@pytest.mark.parametrize("tolerance", [0.0, -0.01, float("nan"), True, "0.02"])
def test_a_target_step_tolerance_that_is_not_a_positive_number_is_refused(human, tolerance):
    with pytest.raises(InputError, match="target_step_tolerance: expected None or a positive number") as raised:
        Tracker(human, settings=TrackingSettings(target_step_tolerance=tolerance))
    assert raised.value.parameter == "target_step_tolerance"
