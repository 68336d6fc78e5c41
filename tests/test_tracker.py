"""Tests of the Tracker: a short synthetic sequence of the human model, blind and with the image."""

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.synthetic.silhouettes import render_silhouettes
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.tracker import Tracker
from ibik_pin.vision.pinhole import look_at_camera
from tests.conftest import random_human_configuration

TARGETS = ["Hip", "LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle", "Neck", "Head",
           "LShoulder", "RShoulder", "LWrist", "RWrist"]
FRAMES = 4


@pytest.fixture(scope="module")
def sequence(human):
    """FRAMES configurations moving smoothly between two seeded poses, and their keypoints (F, K, 3) [m]."""
    rng = np.random.default_rng(31)
    start = random_human_configuration(human, rng, spread=0.3)
    end = random_human_configuration(human, rng, spread=0.3)
    end[:7] = start[:7]  # the same root: the motion is the limbs'
    motion = np.array([pin.interpolate(human.model, start, end, t) for t in np.linspace(0.0, 0.15, FRAMES)])
    frame_ids = human.frame_ids(TARGETS)
    targets = np.array([Configuration(human.model, q).frame_positions(frame_ids) for q in motion])
    return motion, targets


def fast_settings(**overrides) -> TrackingSettings:
    return TrackingSettings(**{"iterations": 10, "first_frame_iterations": 40, **overrides})


def test_blind_tracking_reaches_every_target_of_every_frame(human, sequence):
    _, targets = sequence
    result = Tracker(human, settings=fast_settings()).track(TARGETS, targets)
    assert result.q.shape == (FRAMES, human.model.nq)
    assert result.target_distances.shape == (FRAMES, len(TARGETS))
    assert np.nanmax(result.target_distances) < 1e-4
    assert np.all(np.isnan(result.overlap))  # no camera, no overlap
    assert result.dropped_targets == [[]] * FRAMES


def test_a_step_tolerance_ends_converged_frames_early_and_the_steps_are_recorded(human, sequence):
    _, targets = sequence
    fixed = Tracker(human, settings=fast_settings(iterations=20)).track(TARGETS, targets)
    early = Tracker(human, settings=fast_settings(iterations=20, step_tolerance=1e-3)).track(TARGETS, targets)
    assert fixed.iterations[1:] == [20] * (FRAMES - 1)
    assert all(steps < 20 for steps in early.iterations[1:]), early.iterations
    assert np.nanmax(early.target_distances) < 1e-4


def test_every_frame_keeps_the_solvers_report_of_each_level(human, sequence):
    _, targets = sequence
    # 20 steps: with 10 the upper level ends some 1e-6 m short on most seeds, reported "relaxed"
    result = Tracker(human, settings=fast_settings(iterations=20)).track(TARGETS, targets)
    assert result.level_names == ["lower-body targets", "upper-body targets", "posture"]
    assert len(result.level_reports) == FRAMES
    for reports in result.level_reports:
        assert [report.kind for report in reports] == ["tasks", "tasks", "tasks"]
        assert [report.status for report in reports[:2]] == ["solved", "solved"]
        assert all(np.isfinite(report.residual) for report in reports)


def test_a_target_absent_in_one_frame_is_reported_dropped(human, sequence):
    _, targets = sequence
    targets = targets.copy()
    wrist = TARGETS.index("LWrist")
    targets[2, wrist] = np.nan
    result = Tracker(human, settings=fast_settings()).track(TARGETS, targets)
    assert result.dropped_targets[2] == ["LWrist"]
    assert np.isnan(result.target_distances[2, wrist])
    assert np.isfinite(np.delete(result.target_distances[2], wrist)).all()


def test_tracking_with_the_image_reports_the_image_level_and_the_overlap(human, sequence):
    motion, targets = sequence
    cameras, masks = _two_views(human, motion)
    tracker = Tracker(human, cameras, fast_settings(iterations=5, first_frame_iterations=20))
    result = tracker.track(TARGETS, targets, silhouettes=lambda frame: masks[frame])
    assert result.level_names == ["lower-body targets", "upper-body targets", "image", "posture"]
    for reports in result.level_reports:
        image = reports[2]
        assert (image.kind, image.status) == ("gradient", "solved")
        assert np.isnan(image.residual) and np.isfinite(image.value)
    assert result.overlap.shape == (FRAMES, 2)
    assert result.overlap.min() > 0.5  # the skeleton lies inside both silhouettes
    assert np.nanmax(result.target_distances) < 2e-3


def test_reading_ahead_in_a_process_or_a_thread_gives_the_same_motion_as_on_one_thread(human, sequence):
    motion, targets = sequence
    cameras, masks = _two_views(human, motion)
    results = [Tracker(human, cameras, fast_settings(iterations=5, first_frame_iterations=20, read_ahead=ahead))
               .track(TARGETS, targets, silhouettes=lambda frame: masks[frame])
               for ahead in ("process", "thread", "off")]
    for result in results[:2]:
        np.testing.assert_array_equal(result.q, results[2].q)
        np.testing.assert_array_equal(result.overlap, results[2].overlap)
        assert result.loop_seconds > 0.0
    assert results[2].loop_seconds >= results[2].solve_seconds > 0.0
    with pytest.raises(InputError, match="read_ahead: expected one of process, thread, off"):
        Tracker(human, cameras, fast_settings(read_ahead=True))


def test_level_outcomes_computed_in_the_image_process_are_those_computed_in_the_tracker(human, sequence,
                                                                                          monkeypatch):
    """The child's copy of the tracker, set as the frame had it (its targets, one dropped; its
    images; a posture on the previous frame), gives every frame's level outcomes to the bit."""
    from ibik_pin.readahead.image_process import ImageProcess
    from ibik_pin.tracking.stack import Stack

    motion, targets = sequence
    targets = targets.copy()
    targets[2, TARGETS.index("LWrist")] = np.nan
    cameras, masks = _two_views(human, motion)
    stack = Stack.from_dict({"level": [
        {"tasks": [{"kind": "position"}]},
        {"tasks": [{"kind": "image"}]},
        {"tasks": [{"kind": "posture", "reference": "previous", "weight": 0.1}]},
    ]})
    settings = fast_settings(iterations=5, first_frame_iterations=20, stack=stack)
    offloaded = []
    submit = ImageProcess.submit

    def counted(self, frame, payload):
        offloaded.append(frame)
        return submit(self, frame, payload)

    monkeypatch.setattr(ImageProcess, "child_is_ahead", lambda self: True)  # every frame to the child
    monkeypatch.setattr(ImageProcess, "submit", counted)
    in_child = Tracker(human, cameras, dataclasses.replace(settings, read_ahead="process")).track(
        TARGETS, targets, silhouettes=lambda frame: masks[frame])
    here = Tracker(human, cameras, dataclasses.replace(settings, read_ahead="off")).track(
        TARGETS, targets, silhouettes=lambda frame: masks[frame])
    assert offloaded == list(range(FRAMES))
    np.testing.assert_array_equal(in_child.q, here.q)
    assert len(in_child.level_outcomes) == FRAMES
    for child_frame, frame in zip(in_child.level_outcomes, here.level_outcomes, strict=True):
        assert [outcome.status for outcome in child_frame] == [outcome.status for outcome in frame]
        np.testing.assert_array_equal([[o.residual, o.sacrificed, o.criterion] for o in child_frame],
                                      [[o.residual, o.sacrificed, o.criterion] for o in frame])
    assert np.isfinite(here.level_outcomes[3][2].residual)  # the posture on the previous frame is counted


def _two_views(human, motion):
    center = Configuration(human.model, motion[0]).frame_position(human.frame_id("Hip"))
    cameras = [look_at_camera(name, (160, 120), 150.0, center + offset, center, np.array([0.0, 1.0, 0.0]))
               for name, offset in [("front", [3.5, 0.3, 0.5]), ("side", [0.4, 0.5, -3.8])]]
    return cameras, [render_silhouettes(human, q, cameras) for q in motion]


def _image_solves(tracker):
    """Spy on the tracker's solver: (q before, q after) of every solve whose levels hold the image."""
    spied, solve = [], tracker.solver.solve

    def spy(configuration, levels, **options):
        before = configuration.q.copy()
        result = solve(configuration, levels, **options)
        if any(tracker.image_criterion in level for level in levels):
            spied.append((before, configuration.q.copy()))
        return result
    tracker.solver.solve = spy
    return spied


@pytest.mark.parametrize("image_moves", ["limbs", "all"])
def test_the_image_steps_move_the_trunk_only_when_asked(human, sequence, image_moves):
    motion, targets = sequence
    # Targets that the trunk cannot meet: the Neck 3 cm forward of where the model can put it.
    targets = targets.copy()
    targets[:, TARGETS.index("Neck"), 0] += 0.03
    cameras, masks = _two_views(human, motion)
    tracker = Tracker(human, cameras, fast_settings(iterations=5, first_frame_iterations=20,
                                                    image_moves=image_moves, swivel_search=False))
    spied = _image_solves(tracker)
    result = tracker.track(TARGETS, targets, silhouettes=lambda frame: masks[frame])
    assert len(spied) == FRAMES  # one solve with the image per frame
    # Velocity coordinates of the root, spine, clavicles and neck: pin.difference measures each move.
    held = ~human.limb_coordinates
    moves = np.array([np.abs(pin.difference(human.model, before, after)[held]).max() for before, after in spied])
    limb_moves = np.array([np.abs(pin.difference(human.model, before, after)[~held]).max() for before, after in spied])
    assert limb_moves.max() > 1e-3  # the image steps do move the limbs
    if image_moves == "limbs":
        assert moves.max() < 1e-9
        assert [reports[2].kind for reports in result.level_reports] == ["gradient"] * FRAMES
    else:
        assert moves.max() > 1e-6


def test_the_image_steps_stop_at_the_criterions_peak_unless_counted(human, sequence):
    """image_stop "count" takes every step; "peak" ends a frame's image steps once the criterion
    stops rising (Solver.solve's stop_at_peak, tested in test_solvers), never before two steps,
    and the targets are still met."""
    motion, targets = sequence
    cameras, masks = _two_views(human, motion)
    counted, peaked = [Tracker(human, cameras, fast_settings(iterations=12, first_frame_iterations=20, image_stop=stop))
                       .track(TARGETS, targets, silhouettes=lambda frame: masks[frame]) for stop in ("count", "peak")]
    assert counted.iterations[1:] == [12] * (FRAMES - 1)
    assert all(2 <= steps <= 12 for steps in peaked.iterations[1:])
    assert sum(peaked.iterations[1:]) < 12 * (FRAMES - 1), peaked.iterations
    assert np.nanmax(peaked.target_distances) < 1e-3


def test_an_unknown_image_stop_is_refused(human):
    with pytest.raises(InputError, match="image_stop: expected one of peak, count, found 'never'"):
        Tracker(human, settings=fast_settings(image_stop="never"))


def test_an_unknown_image_moves_is_refused(human):
    with pytest.raises(InputError, match="image_moves: expected one of limbs, all, found 'trunk'"):
        Tracker(human, settings=fast_settings(image_moves="trunk"))


def test_an_unknown_keypoint_is_refused_with_the_known_ones(human, sequence):
    _, targets = sequence
    with pytest.raises(InputError, match=r"unknown keypoint name\(s\) Tail; known keypoints: .*LWrist"):
        Tracker(human, settings=fast_settings()).track([*TARGETS[:-1], "Tail"], targets)


def test_targets_of_the_wrong_shape_are_refused(human, sequence):
    _, targets = sequence
    with pytest.raises(InputError, match=r"targets must have shape \(F, 13, 3\), got \(4, 12, 3\)"):
        Tracker(human, settings=fast_settings()).track(TARGETS, targets[:, 1:])


def test_cameras_without_silhouettes_are_refused(human, sequence):
    _, targets = sequence
    camera = look_at_camera("front", (160, 120), 150.0, np.array([3.0, 1.0, 0.0]), np.zeros(3),
                            np.array([0.0, 1.0, 0.0]))
    with pytest.raises(InputError, match=r"silhouettes: the image criterion needs them .*settings\.use_image=False"):
        Tracker(human, [camera], fast_settings()).track(TARGETS, targets)


def test_the_first_frames_blind_solve_stops_once_converged(human, rng):
    """From the neutral pose to reachable targets: fewer steps than allowed, the last below the
    tolerance, and the pose of the full count of steps to a micrometre."""
    from ibik_pin.limits import JointLimits
    from ibik_pin.solvers import make_solver
    from ibik_pin.tasks import FramePositionTask, PostureTask
    from ibik_pin.tracking.first_frame import BLIND_CONVERGED, solve_first_frame

    goal = Configuration(human.model, random_human_configuration(human, rng, spread=0.3))
    names = ["LWrist", "RWrist", "LAnkle", "RAnkle", "Head"]
    targets = [FramePositionTask(human.model, human.keypoints[name], goal.frame_position(human.frame_id(name)))
               for name in names]
    start = goal.q.copy()
    start[7:] = pin.neutral(human.model)[7:]
    levels = [targets, [PostureTask(human.model, weight=1e-2)]]
    solver = make_solver("qp", limits=JointLimits(human.model))
    early = Configuration(human.model, start)
    result = solve_first_frame(solver, early, levels, None, iterations=100)
    assert result.iterations < 100 and result.step_norms[-1] < BLIND_CONVERGED
    full = Configuration(human.model, start)
    solver.solve(full, levels, iterations=100)
    keypoints = human.frame_ids(list(human.keypoints))
    np.testing.assert_allclose(early.frame_positions(keypoints), full.frame_positions(keypoints), atol=1e-6)


def test_a_slow_image_process_and_its_claimed_frames_give_the_motion_and_outcomes_of_one_thread(human, monkeypatch):
    """The tracker beside a child held up at one frame (so the parent, waiting for it, claims later
    frames and builds them itself) and then running past the claimed frames, every frame's level
    outcomes handed to the child where it can take them: the motion, the overlaps and the level
    outcomes of a run on one thread, to the bit."""
    import multiprocessing
    import os
    import time

    from ibik_pin.readahead.image_process import MAX_SLOTS, ImageProcess

    frames = 2 * MAX_SLOTS + 8
    rng = np.random.default_rng(5)
    start = random_human_configuration(human, rng, spread=0.3)
    end = random_human_configuration(human, rng, spread=0.3)
    end[:7] = start[:7]
    motion = np.array([pin.interpolate(human.model, start, end, t) for t in np.linspace(0.0, 0.3, frames)])
    frame_ids = human.frame_ids(TARGETS)
    targets = np.array([Configuration(human.model, q).frame_positions(frame_ids) for q in motion])
    cameras, masks = _two_views(human, motion)
    parent = os.getpid()
    read_in_parent = multiprocessing.Array("i", frames)

    def silhouettes(frame):
        if os.getpid() == parent:
            read_in_parent[frame] = 1
        elif frame == MAX_SLOTS:  # the child held up until the parent, waiting for it, has claimed a frame
            deadline = time.monotonic() + 10.0
            while not any(read_in_parent[1:]) and time.monotonic() < deadline:
                time.sleep(0.001)
        return masks[frame]

    settings = fast_settings(iterations=3, first_frame_iterations=10)
    monkeypatch.setattr(ImageProcess, "child_is_ahead", lambda self: True)  # every job offered to the child
    in_process = Tracker(human, cameras, dataclasses.replace(settings, read_ahead="process")).track(
        TARGETS, targets, silhouettes=silhouettes)
    here = Tracker(human, cameras, dataclasses.replace(settings, read_ahead="off")).track(
        TARGETS, targets, silhouettes=lambda frame: masks[frame])
    assert sum(read_in_parent[1:]) > 0  # frames claimed
    np.testing.assert_array_equal(in_process.q, here.q)
    np.testing.assert_array_equal(in_process.overlap, here.overlap)
    for process_frame, frame in zip(in_process.level_outcomes, here.level_outcomes, strict=True):
        assert [outcome.status for outcome in process_frame] == [outcome.status for outcome in frame]
        np.testing.assert_array_equal([[o.residual, o.sacrificed, o.criterion] for o in process_frame],
                                      [[o.residual, o.sacrificed, o.criterion] for o in frame])
