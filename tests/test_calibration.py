"""Subject calibration: known scales and keypoint placements recovered, the URDF round trip, bad input."""

from __future__ import annotations

import copy
import json

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.app.calibrate import parse_frame_range
from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import prepare_body
from ibik_pin.cli import main
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.human import human_urdf_path, load_human
from ibik_pin.io.trc import TrcData, write_trc
from ibik_pin.subject.calibration import (
    JOINT_CENTRE_KEYPOINTS,
    SCALE_GROUPS,
    CalibrationSettings,
    calibrate_static_trial,
    calibrate_subject,
)
from ibik_pin.subject.urdf import write_subject_urdf

MILLIMETRE = 1e-3
# Known segment scales; the pelvis 2 cm wider (the hip centres 2 cm farther apart).
SCALES = {"left_thigh": 1.06, "right_thigh": 1.04, "left_shank": 0.95, "right_shank": 0.96, "trunk": 1.05,
          "left_upper_arm": 1.03, "right_upper_arm": 1.02, "left_forearm": 0.97, "right_forearm": 0.98,
          "shoulder_width": 0.9, "pelvis_width": 1.0 + 0.02 / 0.164}
# Known keypoint placements [m]: the data set's Neck 4 cm behind the model's, its Head 5 cm forward,
# its shoulders 3 cm above the shoulder joints (on the trunk, as an acromion is).
OFFSETS = {"Neck": (-0.04, 0.0, 0.0), "Head": (0.05, 0.0, 0.0), "LShoulder": (0.0, 0.03, 0.0),
           "RShoulder": (0.0, 0.03, 0.0)}
NAMES = ["Hip", "LHip", "LKnee", "LAnkle", "LBigToe", "LSmallToe", "LHeel", "RHip", "RKnee", "RAnkle", "RBigToe",
         "RSmallToe", "RHeel", "Neck", "Head", "Nose", "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow", "RWrist"]
# The recovery test's protocol: trunk and head held upright (their posture weighs), the limbs moved
# through a few poses, exact data (the placements and lengths weigh little against it).
PROTOCOL = CalibrationSettings(offset_weight=0.003, scale_weight=0.003, spine_posture_weight=1.0,
                               clavicle_posture_weight=1.0, neck_posture_weight=1.0)


def perturbed_human():
    """The human with the known scales, and the keypoints moved by the known offsets.

    A keypoint at its joint's origin is moved on the proximal segment (its parent joint's frame),
    where the calibration places such keypoints.
    """
    body = load_human()
    model = body.model
    for group, scale in SCALES.items():
        for joint, axes in SCALE_GROUPS[group]:
            index = model.getJointId(joint)
            placement = model.jointPlacements[index].copy()
            placement.translation = placement.translation * (1.0 + (scale - 1.0) * np.asarray(axes))
            model.jointPlacements[index] = placement
    for name, offset in OFFSETS.items():
        frame_id = body.frame_id(name)
        frame = model.frames[frame_id]
        joint = frame.parentJoint
        if np.allclose(frame.placement.translation, 0.0):
            frame.placement = model.jointPlacements[joint] * pin.SE3(np.eye(3), np.asarray(offset))
            frame.parentJoint = model.parents[joint]
        else:
            frame.placement = pin.SE3(frame.placement.rotation, frame.placement.translation + np.asarray(offset))
        model.frames[frame_id] = frame
    return body


def static_poses(body, rng, frames: int) -> np.ndarray:
    """Keypoints (F, K, 3) [m] of the body standing with its trunk and head upright, the limbs in
    a different pose each frame (the first neutral), anywhere in the room."""
    model, data = body.model, body.model.createData()
    moved = ("hip_Z", "hip_X", "knee_Z", "shoulder_Z", "shoulder_X", "elbow_Z")
    positions = np.empty((frames, len(NAMES), 3))
    for frame in range(frames):
        q = pin.neutral(model)
        for joint in range(2, model.njoints):
            if frame > 0 and model.names[joint].endswith(moved):
                index = model.idx_qs[joint]
                q[index] = np.clip(rng.uniform(-0.5, 0.5), model.lowerPositionLimit[index],
                                   model.upperPositionLimit[index])
        q[:3] = rng.normal(0.0, 0.5, 3)
        q[3:7] = pin.Quaternion(pin.exp3(np.array([0.0, rng.uniform(-3.0, 3.0), 0.0]))).coeffs()
        pin.framesForwardKinematics(model, data, q)
        positions[frame] = [data.oMf[body.frame_id(name)].translation for name in NAMES]
    return positions


def neutral_layout(body) -> np.ndarray:
    """Every keypoint of NAMES at the neutral pose, relative to the midpoint of the hips, (K, 3) [m]."""
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, pin.neutral(body.model))
    points = np.array([data.oMf[body.frame_id(name)].translation for name in NAMES])
    return points - 0.5 * (points[NAMES.index("LHip")] + points[NAMES.index("RHip")])


def placement_on_joint(body, name: str) -> np.ndarray:
    """Where a keypoint sits in its parent joint's frame, relative to the child joint it may sit on
    (the offset of OFFSETS), shape (3,) [m]."""
    model = body.model
    frame = model.frames[body.frame_id(name)]
    children = [j for j in range(1, model.njoints) if model.parents[j] == frame.parentJoint]
    anchors = [j for j in children if np.linalg.norm(model.jointPlacements[j].translation - frame.placement.translation)
               < 0.1 and name not in ("Head", "Nose")]
    base = model.jointPlacements[anchors[0]].translation if anchors else 0.0
    return frame.placement.translation - base


@pytest.fixture(scope="module")
def recovery():
    truth = perturbed_human()
    positions = static_poses(truth, np.random.default_rng(7), frames=4)
    return truth, positions, calibrate_subject(load_human(), NAMES, positions, PROTOCOL)


def test_calibration_reproduces_the_static_keypoints_to_a_millimetre(recovery):
    _, _, result = recovery
    assert result.keypoint_names == NAMES
    assert np.max(result.residual_after[:, 1]) < MILLIMETRE
    assert np.mean(result.residual_before[:, 0]) > 5 * MILLIMETRE  # lengths-only scaling could not


def test_calibration_recovers_the_known_segment_lengths(recovery):
    truth, _, result = recovery
    for joint in ("left_knee_Z", "right_knee_Z", "left_ankle_Z", "right_ankle_Z", "left_elbow_Z", "right_elbow_Z",
                  "left_wrist_Z", "right_wrist_Z"):
        calibrated = result.body.model.jointPlacements[result.body.model.getJointId(joint)].translation
        known = truth.model.jointPlacements[truth.model.getJointId(joint)].translation
        assert np.linalg.norm(calibrated - known) < MILLIMETRE, joint
    for joint in ("left_hip_Z", "left_shoulder_Z"):  # pelvis and shoulder widths
        calibrated = result.body.model.jointPlacements[result.body.model.getJointId(joint)].translation[2]
        known = truth.model.jointPlacements[truth.model.getJointId(joint)].translation[2]
        assert abs(calibrated - known) < MILLIMETRE, joint


def test_calibration_recovers_the_known_placements(recovery):
    truth, _, result = recovery
    for name, offset in OFFSETS.items():
        recovered = placement_on_joint(result.body, name)
        known = placement_on_joint(truth, name)
        # The trunk never bends in this static trial: its length and the height of Neck and Head
        # on it only show together, so those two are judged across the trunk (x, z) here and
        # whole in the layout test below.
        axes = [0, 2] if name in ("Neck", "Head") else [0, 1, 2]
        assert np.all(np.abs(recovered - known)[axes] < MILLIMETRE), (name, recovered, known, offset)
    # Every keypoint where the subject has it, the trunk's trade included; a few tenths of a
    # millimetre of each segment add up at the wrists.
    assert np.max(np.linalg.norm(neutral_layout(result.body) - neutral_layout(truth), axis=1)) < 2 * MILLIMETRE


def test_joint_centres_stay_joint_centres_on_one_standing_frame():
    truth = perturbed_human()
    positions = static_poses(truth, np.random.default_rng(3), frames=1)
    result = calibrate_subject(load_human(), NAMES, positions)
    moved = {name: 1000 * np.linalg.norm(result.offsets[k]) for k, name in enumerate(NAMES)}
    assert all(moved[name] < 2.0 for name in JOINT_CENTRE_KEYPOINTS if name in moved), moved
    assert np.mean(result.residual_after[:, 0]) < 0.25 * np.mean(result.residual_before[:, 0])
    assert result.body.calibrated


def test_a_missing_cell_drops_that_keypoint_in_that_frame_only(recovery):
    _, positions, _ = recovery
    holed = positions.copy()
    holed[1, NAMES.index("Head")] = np.nan
    holed[2, NAMES.index("LWrist")] = np.nan
    result = calibrate_subject(load_human(), NAMES, holed, PROTOCOL)
    assert np.max(result.residual_after[:, 1]) < MILLIMETRE


def test_the_saved_urdf_reloads_with_the_same_keypoints(recovery, tmp_path):
    _, _, result = recovery
    notes = write_subject_urdf(result.body, tmp_path / "subject.urdf")
    assert notes == []  # the installed meshes were found
    reloaded = load_human(tmp_path / "subject.urdf")
    assert reloaded.calibrated
    assert list(reloaded.keypoints) == list(result.body.keypoints)
    rng = np.random.default_rng(1)
    for q in (pin.neutral(reloaded.model), pin.randomConfiguration(reloaded.model, -np.ones(45), np.ones(45))):
        q[:3] = rng.normal(size=3)
        first, second = result.body.model.createData(), reloaded.model.createData()
        pin.framesForwardKinematics(result.body.model, first, q)
        pin.framesForwardKinematics(reloaded.model, second, q)
        for name in reloaded.keypoints:
            saved = first.oMf[result.body.frame_id(name)].translation
            assert np.linalg.norm(saved - second.oMf[reloaded.frame_id(name)].translation) < 1e-9, name
    np.testing.assert_allclose(reloaded.segment_radii, result.body.segment_radii, rtol=1e-9)
    geometry = pin.buildGeomFromUrdf(reloaded.model, str(tmp_path / "subject.urdf"), pin.GeometryType.VISUAL)
    assert geometry.ngeoms > 0


def test_a_calibrated_model_is_not_scaled_again_by_tracking(recovery, tmp_path):
    _, positions, result = recovery
    write_subject_urdf(result.body, tmp_path / "subject.urdf")
    job = TrackJob(targets=tmp_path / "targets.trc", out=tmp_path / "out", model=tmp_path / "subject.urdf")
    targets = 1.3 * positions  # a taller subject's targets would re-scale an uncalibrated model
    body = prepare_body(job, NAMES, targets)
    np.testing.assert_allclose(neutral_layout(body), neutral_layout(result.body), atol=1e-9)


def write_static(path, positions, names=NAMES, units="m") -> None:
    frames = positions.shape[0]
    write_trc(path, TrcData(marker_names=list(names), times=np.arange(frames) / 60.0, positions=positions,
                            units=units, data_rate=60.0, frame_numbers=np.arange(1, frames + 1)))


def test_ibik_calibrate_writes_the_urdf_and_the_figures(recovery, tmp_path, capsys):
    _, positions, _ = recovery
    write_static(tmp_path / "static.trc", positions)
    code = main(["calibrate", str(tmp_path / "static.trc"), "--out", str(tmp_path / "subject.urdf"),
                 "--frames", "2:3"])
    assert code == 0
    figures = json.loads((tmp_path / "subject.calibration.json").read_text())
    assert figures["trc_frame_numbers"] == [2, 3]
    assert set(figures["keypoints"]) == set(NAMES)
    assert figures["keypoints"]["Neck"]["after_mm"]["mean"] < figures["keypoints"]["Neck"]["before_mm"]["mean"]
    assert load_human(tmp_path / "subject.urdf").calibrated
    assert "Neck" in capsys.readouterr().out


@pytest.mark.parametrize(("case", "message"), [
    ("millimetres labelled metres", "the data look like mm"),
    ("every cell empty", "every cell is empty"),
    ("four keypoints", "at least 6 keypoints"),
    ("unknown name", "unknown keypoint name(s) Elbow"),
    ("frames outside the trial", "no frame numbered 7:9"),
])
def test_ibik_calibrate_refuses_bad_static_trials_in_one_line(recovery, tmp_path, capsys, case, message):
    _, positions, _ = recovery
    names, units, frames = list(NAMES), "m", []
    if case == "millimetres labelled metres":
        positions = positions * 1000.0
    elif case == "every cell empty":
        positions = np.full_like(positions, np.nan)
    elif case == "four keypoints":
        names, positions = names[:4], positions[:, :4]
    elif case == "unknown name":
        names[NAMES.index("LElbow")] = "Elbow"
    else:
        frames = ["--frames", "7:9"]
    write_static(tmp_path / "static.trc", positions, names, units)
    code = main(["calibrate", str(tmp_path / "static.trc"), "--out", str(tmp_path / "subject.urdf"), *frames])
    error = capsys.readouterr().err
    assert code == 2
    assert error.count("\n") == 1 and error.startswith("ibik: error:") and message in error, error
    assert not (tmp_path / "subject.urdf").exists()


def test_calibrate_subject_names_the_problem():
    human = load_human()
    with pytest.raises(UnknownNameError, match="unknown keypoint name"):
        calibrate_subject(human, ["Hip", "Elbow"], np.zeros((1, 2, 3)))
    with pytest.raises(InputError, match="expected positions of shape"):
        calibrate_subject(human, ["Hip", "LHip"], np.zeros((1, 3, 3)))
    two_per_frame = np.full((3, 6, 3), np.nan)
    for frame in range(3):
        two_per_frame[frame, 2 * frame:2 * frame + 2] = 0.1 * frame
    with pytest.raises(InputError, match="no frame holds 3 keypoints"):
        calibrate_subject(human, NAMES[:6], two_per_frame)
    with pytest.raises(InputError, match="FIRST:LAST"):
        parse_frame_range("3-4")
    with pytest.raises(InputError, match="FIRST must not be after LAST"):
        parse_frame_range("5:2")
    assert parse_frame_range(":7") == (None, 7)


def test_settings_refuse_negative_weights():
    with pytest.raises(InputError, match="offset_weight"):
        CalibrationSettings(offset_weight=-1.0)


def test_calibrating_a_file_keeps_its_frame_numbers(recovery, tmp_path):
    _, positions, _ = recovery
    write_static(tmp_path / "static.trc", positions)
    result = calibrate_static_trial(tmp_path / "static.trc", copy.deepcopy(load_human()), (3, None), PROTOCOL)
    assert list(result.frame_numbers) == [3, 4]


def test_a_calibrated_subject_is_not_calibrated_again(recovery, tmp_path):
    _, positions, result = recovery
    write_subject_urdf(result.body, tmp_path / "subject.urdf")
    with pytest.raises(InputError, match="already a calibrated subject"):
        calibrate_subject(load_human(tmp_path / "subject.urdf"), NAMES, positions)


def test_targets_in_millimetres_labelled_metres_are_refused_before_scaling(recovery, tmp_path):
    _, positions, _ = recovery
    job = TrackJob(targets=tmp_path / "targets.trc", out=tmp_path / "out")
    with pytest.raises(InputError, match="the data look like mm"):
        prepare_body(job, NAMES, 1000.0 * positions)


def test_a_mesh_that_cannot_be_found_is_dropped_with_a_note(tmp_path):
    source = tmp_path / "human.urdf"
    text = human_urdf_path().read_text()
    source.write_text(text.replace("package://example-robot-data/robots/human_description/meshes/pelvis_mesh.STL",
                                   "meshes/missing.STL", 1))
    notes = write_subject_urdf(load_human(source), tmp_path / "subject.urdf")
    assert len(notes) == 1 and "middle_pelvis" in notes[0] and "missing.STL" in notes[0]
    written = (tmp_path / "subject.urdf").read_text()
    assert "missing.STL" not in written
    assert written.count("<mesh ") == text.count("<mesh ") - 1
    assert "file://" in written and "package://" not in written


def test_ibik_calibrate_refuses_to_write_over_its_own_model(recovery, tmp_path, capsys):
    _, positions, _ = recovery
    write_static(tmp_path / "static.trc", positions)
    assert main(["calibrate", str(tmp_path / "static.trc"), "--out", str(tmp_path / "subject.urdf")]) == 0
    before = (tmp_path / "subject.urdf").read_bytes()
    code = main(["calibrate", str(tmp_path / "static.trc"), "--model", str(tmp_path / "subject.urdf"),
                 "--out", str(tmp_path / "subject.urdf")])
    error = capsys.readouterr().err
    assert code == 2 and error.count("\n") == 1 and "it is --model" in error
    assert (tmp_path / "subject.urdf").read_bytes() == before
