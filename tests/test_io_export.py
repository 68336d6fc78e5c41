"""Tests of ibik_pin.io.export: configurations to CSV, joint angles to OpenSim .mot, the model's
motion to BVH, each read back with an independent reader."""

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from ibik_pin.exceptions import InputError
from ibik_pin.io.bvh import read_bvh
from ibik_pin.io.export import (
    bvh_joint_groups,
    q_column_names,
    q_column_units,
    write_model_bvh,
    write_model_mot,
    write_q_csv,
)
from ibik_pin.io.mot import read_mot
from ibik_pin.model import load_arm
from tests.conftest import random_human_configuration

FRAME_COUNT = 10
FRAME_TIME = 0.01  # [s]
BVH_POSITION_TOLERANCE = 1e-3  # [m]: the BVH positions within 1 mm
ANGLE_TOLERANCE = 1e-9  # [deg]

# The human's BVH joints: name -> model joints, and end site -> keypoint frame.
HUMAN_BVH_GROUPS = {
    "root": ["root_joint"],
    "left_hip": ["left_hip_Z", "left_hip_X", "left_hip_Y"],
    "left_knee": ["left_knee_Z"],
    "left_ankle": ["left_ankle_Y", "left_ankle_Z", "left_ankle_X"],
    "middle_lumbar": ["middle_lumbar_Z", "middle_lumbar_X"],
    "middle_thoracic": ["middle_thoracic_Z", "middle_thoracic_X", "middle_thoracic_Y"],
    "left_clavicle": ["left_clavicle_joint_X"],
    "left_shoulder": ["left_shoulder_Z", "left_shoulder_X", "left_shoulder_Y"],
    "left_elbow": ["left_elbow_Z", "left_elbow_Y"],
    "left_wrist": ["left_wrist_Z", "left_wrist_X"],
    "middle_cervical": ["middle_cervical_Z", "middle_cervical_X", "middle_cervical_Y"],
    "right_clavicle": ["right_clavicle_joint_X"],
    "right_shoulder": ["right_shoulder_Z", "right_shoulder_X", "right_shoulder_Y"],
    "right_elbow": ["right_elbow_Z", "right_elbow_Y"],
    "right_wrist": ["right_wrist_Z", "right_wrist_X"],
    "right_hip": ["right_hip_Z", "right_hip_X", "right_hip_Y"],
    "right_knee": ["right_knee_Z"],
    "right_ankle": ["right_ankle_Y", "right_ankle_Z", "right_ankle_X"],
}
HUMAN_BVH_END_SITES = {
    "left_ankle_end": "LBigToe",
    "left_wrist_end": "LHand",
    "middle_cervical_end": "Head",
    "right_wrist_end": "RHand",
    "right_ankle_end": "RBigToe",
}


@pytest.fixture
def motion(human, rng):
    """Times (F,) [s] and configurations (F, nq) anywhere within the joint limits."""
    q = np.array([random_human_configuration(human, rng, spread=1.0) for _ in range(FRAME_COUNT)])
    return FRAME_TIME * np.arange(FRAME_COUNT), q


def world_positions(model, q, frame_names, joint_names):
    """Pinocchio's world positions of frames then joint origins, shape (F, len(both), 3) [m]."""
    data = model.createData()
    positions = []
    for configuration in q:
        pin.framesForwardKinematics(model, data, configuration)
        # .copy(): Pinocchio returns views into data, overwritten by the next frame.
        frames = [data.oMf[model.getFrameId(name)].translation.copy() for name in frame_names]
        joints = [data.oMi[model.getJointId(name)].translation.copy() for name in joint_names]
        positions.append(frames + joints)
    return np.array(positions)


def test_q_column_names_give_the_root_position_and_quaternion_then_each_joint_by_name(human):
    names = q_column_names(human.model)

    assert len(names) == human.model.nq
    assert names[:7] == ["root_tx", "root_ty", "root_tz", "root_qx", "root_qy", "root_qz", "root_qw"]
    assert names[7:10] == ["left_hip_Z", "left_hip_X", "left_hip_Y"]
    assert names[-1] == "right_ankle_X"


def test_csv_read_back_with_loadtxt_gives_the_exact_times_and_configurations(
    human, motion, tmp_path
):
    times, q = motion
    path = tmp_path / "q.csv"

    write_q_csv(path, human.model, times, q)

    header = path.read_text().splitlines()[0].split(",")
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    units = q_column_units(human.model)
    assert header == ["time [s]", *[f"{n} [{u}]" for n, u in zip(q_column_names(human.model), units, strict=True)]]
    assert header[1:8] == ["root_tx [m]", "root_ty [m]", "root_tz [m]", "root_qx [1]", "root_qy [1]", "root_qz [1]",
                           "root_qw [1]"]
    assert set(units[7:]) == {"rad"}
    np.testing.assert_array_equal(table[:, 0], times)
    np.testing.assert_array_equal(table[:, 1:], q)


def test_mot_is_read_by_read_mot_in_degrees_with_a_column_per_coordinate(
    human, motion, tmp_path
):
    times, q = motion
    path = tmp_path / "motion.mot"

    write_model_mot(path, human.model, times, q)

    data = read_mot(path)
    joint_count = human.model.njoints - 2  # the universe and the free flyer excluded
    assert data.header["inDegrees"] == "yes"
    assert data.in_degrees
    assert int(data.header["nColumns"]) == 1 + 6 + joint_count == 45
    assert data.column_names[:6] == [
        "pelvis_tx", "pelvis_ty", "pelvis_tz", "pelvis_tilt", "pelvis_list", "pelvis_rotation"
    ]
    assert data.column_names[6:] == q_column_names(human.model)[7:]
    np.testing.assert_array_equal(data.times, times)


def test_mot_holds_the_root_position_its_zxy_euler_angles_and_joint_angles_in_degrees(
    human, motion, tmp_path
):
    times, q = motion
    path = tmp_path / "motion.mot"

    write_model_mot(path, human.model, times, q)

    data = read_mot(path)
    rebuilt = Rotation.from_euler("ZXY", data.values[:, 3:6], degrees=True).as_matrix()
    expected = np.array([pin.Quaternion(quaternion).matrix() for quaternion in q[:, 3:7]])
    np.testing.assert_allclose(data.values[:, :3], q[:, :3], atol=1e-12)
    np.testing.assert_allclose(rebuilt, expected, atol=1e-12)
    np.testing.assert_allclose(data.values[:, 6:], np.rad2deg(q[:, 7:]), atol=ANGLE_TOLERANCE)


def test_mot_root_angles_turning_past_180_degrees_do_not_jump_by_360(human, tmp_path):
    yaw = np.deg2rad(np.linspace(150.0, 210.0, 7))  # about the vertical Y axis
    q = np.tile(pin.neutral(human.model), (yaw.size, 1))
    q[:, 3:7] = [pin.Quaternion(pin.rpy.rpyToMatrix(0.0, angle, 0.0)).coeffs() for angle in yaw]
    path = tmp_path / "turn.mot"

    write_model_mot(path, human.model, np.arange(yaw.size) * FRAME_TIME, q)

    rotation = read_mot(path).values[:, 5]
    assert np.all(np.abs(np.diff(rotation)) < 10.0 + ANGLE_TOLERANCE)
    np.testing.assert_allclose(np.abs(rotation[-1] - rotation[0]), 60.0, atol=1e-9)


def test_bvh_joints_of_the_human_gather_the_joints_that_share_an_origin(human):
    groups = bvh_joint_groups(human.model)

    found = {
        group.name: [human.model.names[joint_id] for joint_id in group.joint_ids]
        for group in groups
    }
    assert found == HUMAN_BVH_GROUPS
    parents = {group.name: groups[group.parent].name for group in groups if group.parent >= 0}
    assert parents["left_knee"] == "left_hip"
    assert parents["middle_cervical"] == "middle_thoracic"
    assert parents["left_hip"] == parents["middle_lumbar"] == "root"


def test_bvh_read_back_puts_every_joint_on_the_model_joint_within_1_mm(human, motion, tmp_path):
    _, q = motion
    path = tmp_path / "motion.bvh"

    write_model_bvh(path, human, q, FRAME_TIME)

    bvh = read_bvh(path, scale=1.0)
    skeleton_motion = bvh.to_skeleton_motion()
    assert bvh.frame_time == FRAME_TIME
    assert sorted(skeleton_motion.names) == sorted([*HUMAN_BVH_GROUPS, *HUMAN_BVH_END_SITES])
    names = list(HUMAN_BVH_END_SITES) + list(HUMAN_BVH_GROUPS)
    expected = world_positions(
        human.model,
        q,
        frame_names=list(HUMAN_BVH_END_SITES.values()),
        joint_names=[joints[0] for joints in HUMAN_BVH_GROUPS.values()],
    )
    found = skeleton_motion.positions[:, [skeleton_motion.index(name) for name in names]]
    errors = np.linalg.norm(found - expected, axis=-1)
    assert errors.max() < BVH_POSITION_TOLERANCE, names[int(np.argmax(errors.max(axis=0)))]


def test_bvh_of_a_model_without_free_flyer_keeps_its_root_at_the_world_origin(rng, tmp_path):
    arm = load_arm()
    model = arm.model
    q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit, (FRAME_COUNT, model.nq))
    path = tmp_path / "arm.bvh"

    write_model_bvh(path, arm, q, FRAME_TIME)

    skeleton_motion = read_bvh(path, scale=1.0).to_skeleton_motion()
    names = ["elbow_end", "root", "shoulder", "elbow"]
    expected = world_positions(
        model, q, frame_names=["wrist"], joint_names=["universe", "shoulder_Z", "elbow_Z"]
    )
    found = skeleton_motion.positions[:, [skeleton_motion.index(name) for name in names]]
    np.testing.assert_allclose(found, expected, atol=BVH_POSITION_TOLERANCE)


def test_exports_name_the_wrong_configuration_shape(human, tmp_path):
    q = np.zeros((FRAME_COUNT, human.model.nq - 1))

    with pytest.raises(InputError, match=r"q: expected shape \(F, 45\)"):
        write_model_bvh(tmp_path / "motion.bvh", human, q, FRAME_TIME)
    with pytest.raises(InputError, match=r"q: expected shape \(F, 45\)"):
        write_q_csv(tmp_path / "q.csv", human.model, np.zeros(FRAME_COUNT), q)
    assert list(tmp_path.iterdir()) == []


def test_exports_refuse_a_root_quaternion_that_is_not_of_unit_norm(human, motion, tmp_path):
    times, q = motion
    q[4, 3:7] *= 1.1

    with pytest.raises(InputError, match=r"unit quaternion.*at frame 4"):
        write_model_mot(tmp_path / "motion.mot", human.model, times, q)


def test_csv_refuses_times_of_another_length(human, motion, tmp_path):
    times, q = motion

    with pytest.raises(InputError, match=r"times: expected 10 finite times"):
        write_q_csv(tmp_path / "q.csv", human.model, times[:-1], q)


def test_bvh_refuses_a_non_positive_frame_time(human, motion, tmp_path):
    _, q = motion

    with pytest.raises(InputError, match=r"frame_time: expected a positive number \[s\], got 0"):
        write_model_bvh(tmp_path / "motion.bvh", human, q, 0.0)
