"""Tests of ibik_pin.app.report: the typed report, its strict JSON and the console summary."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ibik_pin.app.axes import AxesChoice, AxesScore
from ibik_pin.app.report import ResidualStats, TrackingReport
from ibik_pin.tracking.outcomes import LevelOutcome
from ibik_pin.tracking.result import TrackingResult
from ibik_pin.tracking.settings import TrackingSettings
from tests.report_checks import undefined_keys


def refuse_constant(token):
    raise ValueError(f"non-JSON constant {token}")


def tracking_result() -> TrackingResult:
    """3 frames, 2 targets (RWrist absent in the second frame), 1 view disabled in the third."""
    distances = np.array([[0.010, 0.050], [0.020, np.nan], [0.030, 0.070]])
    return TrackingResult(
        q=np.zeros((3, 7)),
        keypoint_names=["Hip", "RWrist"],
        keypoints=np.zeros((3, 2, 3)),
        target_residuals=np.nanmean(distances, axis=1),
        overlap=np.array([[0.9], [0.8], [np.nan]]),
        inside_fraction=np.array([[1.0], [0.75], [np.nan]]),
        limit_hits=[[], ["right_elbow_Z"], []],
        dropped_targets=[[], ["RWrist"], []],
        disabled_views=[[], [], ["cam1"]],
        solve_seconds=0.5,
        loop_seconds=0.75,
        target_names=["Hip", "RWrist"],
        target_distances=distances,
        level_names=["lower-body targets", "posture"],
        level_outcomes=[[LevelOutcome(first, 0.01, 0.0, np.nan), LevelOutcome("relaxed", 0.2, sacrificed, np.nan)]
                        for first, sacrificed in (("solved", 0.5), ("relaxed", np.nan), ("solved", 0.3))],
    )


@pytest.fixture
def report() -> TrackingReport:
    choice = AxesChoice("z-up", "detected", "images",
                        (AxesScore("y-up", 0.44, None, 0.1), AxesScore("z-up", 1.0, None, 0.97)), (0, 2))
    return TrackingReport.from_tracking(tracking_result(), TrackingSettings(), ["cam1"],
                                        np.array([1, 2, 3]), np.array([0.0, 0.01, 0.02]), 100.0, choice)


def test_residual_statistics_skip_absent_frames_and_write_them_as_none():
    stats = ResidualStats.from_values(np.array([0.01, np.nan, 0.04, 0.02]))
    assert (stats.mean, stats.median, stats.max) == pytest.approx((0.07 / 3, 0.02, 0.04), abs=1e-15)
    assert stats.per_frame[1] is None
    never = ResidualStats.from_values(np.full(2, np.nan))
    assert (never.mean, never.median, never.max, never.per_frame) == (None, None, None, [None, None])


def test_the_json_is_strict_and_holds_null_where_values_are_missing(report):
    text = report.to_json()
    parsed = json.loads(text, parse_constant=refuse_constant)
    assert parsed["keypoint_residual_m"]["RWrist"]["per_frame"] == [0.05, None, 0.07]
    assert parsed["overlap_per_view"]["cam1"] == [0.9, 0.8, None]
    assert parsed["solve_frames_per_second"] == pytest.approx(6.0)
    assert parsed["frames_per_second"] == pytest.approx(4.0)  # the whole loop: 3 frames in 0.75 s


def test_frames_are_keyed_by_the_trc_s_frame_numbers(report):
    parsed = json.loads(report.to_json())
    assert parsed["frames_with_dropped_targets"] == {"2": ["RWrist"]}
    assert parsed["joint_limit_hits"] == {"2": ["right_elbow_Z"]}
    assert parsed["frames_with_disabled_views"] == {"3": ["cam1"]}
    assert parsed["frame_numbers"] == [1, 2, 3] and parsed["frame_rate_hz"] == 100.0
    assert parsed["trc_axes"]["sampled_frames"] == [1, 3]
    assert parsed["trc_axes"]["inside_images"] == {"y-up": 0.44, "z-up": 1.0}
    assert parsed["trc_axes"]["inside_silhouettes"] == {}


def test_each_level_s_status_residual_and_sacrifice_are_reported_per_frame(report):
    parsed = json.loads(report.to_json(), parse_constant=refuse_constant)["solver_levels"]
    assert parsed["stack"] == "default"
    assert parsed["levels"] == ["lower-body targets", "posture"]
    assert parsed["status_per_frame"]["lower-body targets"] == ["solved", "relaxed", "solved"]
    assert parsed["frames_per_status"] == {"lower-body targets": {"relaxed": 1, "solved": 2},
                                           "posture": {"relaxed": 3}}
    assert parsed["residual_per_frame"]["posture"] == [0.2, 0.2, 0.2]
    assert parsed["sacrificed_per_frame"]["posture"] == [0.5, None, 0.3]
    assert parsed["mean_sacrificed"]["posture"] == pytest.approx(0.4, abs=1e-12)  # the undefined frame skipped
    assert parsed["mean_residual"]["lower-body targets"] == pytest.approx(0.01, abs=1e-12)
    assert parsed["criterion_per_frame"] == {}  # no image level


def test_the_report_reads_like_its_json(report):
    assert report["end_effector_residual_m"]["max"] == pytest.approx(0.05)
    assert report["trc_axes"]["used"] == "z-up"


def test_an_unmeasured_speed_is_null_not_nan(report):
    report.solve_frames_per_second = float("nan")
    assert json.loads(report.to_json(), parse_constant=refuse_constant)["solve_frames_per_second"] is None


def test_the_summary_lists_the_targets_worst_first_in_millimetres(report):
    lines = report.summary_lines()
    # frames: 30, 20, 50 mm
    assert lines[0] == "3 frames at 4.0 frames/s (the solves alone 6.0), mean end-effector residual 33.3 mm"
    assert lines[2].split() == ["RWrist", "60.0", "(70.0)"]
    assert lines[3].split() == ["Hip", "20.0", "(30.0)"]
    assert len(lines) == 4


def test_write_leaves_a_file_json_loads(report, tmp_path):
    report.write(tmp_path / "report.json")
    assert json.loads((tmp_path / "report.json").read_text(), parse_constant=refuse_constant)["frames"] == 3


def test_report_json_names_the_unit_of_every_figure_and_a_0_1_overlap(report):
    written = json.loads(report.to_json(), parse_constant=refuse_constant)

    figures = [key for key, value in written.items()
               if key not in ("units", "trc_axes", "solver_levels") and not isinstance(value, (str, bool))
               and key not in ("cameras", "frames", "joint_limit_hits", "frames_with_dropped_targets",
                               "frames_with_disabled_views", "frames_with_outlier_targets")]
    assert sorted(key for key in figures if key not in written["units"]) == []
    assert "px" in written["units"]["overlap_per_view"] and "not a 0-1 overlap" in written["units"]["overlap_per_view"]
    assert written["inside_fraction_per_view"] == {"cam1": [1.0, 0.75, None]}
    assert written["solve_seconds"] == 0.5
    assert written["frame_numbers"] == [1, 2, 3] and written["joint_limit_hits"] == {"2": ["right_elbow_Z"]}


def test_every_key_of_report_json_has_a_unit_or_a_definition(report):
    written = json.loads(report.to_json(), parse_constant=refuse_constant)
    units = written["units"]
    assert undefined_keys(written) == []
    assert all(status in units["solver_levels.status_per_frame"] for status in ("solved", "relaxed", "failed"))
