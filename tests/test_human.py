"""Tests of ibik_pin.human: example-robot-data's human with Pose2Sim keypoints, a third axis at
each ankle, and a calibrated subject's keypoint links read back."""

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import FileFormatError
from ibik_pin.human import HUMAN_NEUTRAL_STATURE_M, human_urdf_path, load_human, neutral_stature


def test_the_human_comes_from_the_installed_example_robot_data():
    path = human_urdf_path()
    assert path.name == "human.urdf"
    assert "example-robot-data" in str(path)


def test_the_human_has_38_joints_and_a_free_flyer(human):
    # example-robot-data's 36 and the third axis of each ankle (ibik_pin.feet)
    assert human.model.nq == 45
    assert human.model.nv == 44


def test_the_human_loads_without_a_free_flyer_too():
    body = load_human(free_flyer=False)
    assert body.model.nv == 38
    assert body.frame_id("Hip") >= 0


def test_every_segment_of_the_human_has_a_length_and_a_radius(human):
    data = human.model.createData()
    pin.framesForwardKinematics(human.model, data, pin.neutral(human.model))
    ids = human.segment_frame_ids
    lengths = [np.linalg.norm(data.oMf[int(a)].translation - data.oMf[int(b)].translation) for a, b in ids]
    assert min(lengths) > 0.05
    assert human.segment_radii.shape == (len(human.segments),)


def test_the_human_stands_about_1_75_m_tall(human):
    data = human.model.createData()
    pin.framesForwardKinematics(human.model, data, pin.neutral(human.model))
    head = data.oMf[human.frame_id("Head")].translation
    heel = data.oMf[human.frame_id("LHeel")].translation
    assert 1.6 < head[1] - heel[1] < 1.9


def human_with_keypoint_links(tmp_path, links: dict[str, tuple[str, tuple[float, float, float]]]):
    """The installed human.urdf with keypoint links added: name -> (parent link, origin [m])."""
    text = human_urdf_path().read_text()
    extra = "".join(
        f'<link name="keypoint_{name}"/><joint name="keypoint_{name}_joint" type="fixed"><parent link="{parent}"/>'
        f'<child link="keypoint_{name}"/><origin xyz="{x} {y} {z}" rpy="0 0 0"/></joint>'
        for name, (parent, (x, y, z)) in links.items())
    path = tmp_path / "subject.urdf"
    path.write_text(text.replace("</robot>", extra + "</robot>"))
    return path


def test_the_installed_human_is_not_a_calibrated_subject(human):
    assert not human.calibrated
    assert human.urdf_path == human_urdf_path()


def test_keypoint_links_of_a_urdf_replace_the_default_placements(human, tmp_path):
    path = human_with_keypoint_links(tmp_path, {"LElbow": ("left_upperarm", (0.01, -0.25, 0.0)),
                                                "LEar": ("middle_head", (0.0, 0.1, -0.08))})
    body = load_human(path)
    assert body.calibrated
    assert list(body.keypoints)[:len(human.keypoints)] == list(human.keypoints)
    assert "LEar" in body.keypoints
    data, default = body.model.createData(), human.model.createData()
    q = pin.neutral(body.model)
    pin.framesForwardKinematics(body.model, data, q)
    pin.framesForwardKinematics(human.model, default, q)
    shoulder = data.oMf[body.frame_id("LShoulder")].translation
    assert np.allclose(data.oMf[body.frame_id("LElbow")].translation - shoulder, [0.01, -0.25, 0.0], atol=1e-12)
    assert np.allclose(data.oMf[body.frame_id("LWrist")].translation, default.oMf[human.frame_id("LWrist")].translation)


def test_a_keypoint_link_named_after_a_frame_is_refused(tmp_path):
    path = human_with_keypoint_links(tmp_path, {"middle_pelvis": ("middle_pelvis", (0.0, 0.0, 0.0))})
    with pytest.raises(FileFormatError, match="keypoint_middle_pelvis"):
        load_human(path)


def test_each_ankle_turns_the_foot_outwards_about_the_shank_within_its_limits(human):
    from ibik_pin.feet import FOOT_ROTATION_LIMIT_RAD

    model = human.model
    for side, letter, outwards in [("left", "L", -1.0), ("right", "R", 1.0)]:  # the left side is at -Z
        joint = model.getJointId(f"{side}_ankle_Y")
        index = model.joints[joint].idx_q
        assert model.names[model.parents[joint]] == f"{side}_knee_Z"
        assert model.names[joint + 1] == f"{side}_ankle_Z"
        assert (model.lowerPositionLimit[index], model.upperPositionLimit[index]) == (-FOOT_ROTATION_LIMIT_RAD,
                                                                                      FOOT_ROTATION_LIMIT_RAD)
        q = pin.neutral(model)
        before = Configuration(model, q).frame_position(human.frame_id(f"{letter}BigToe")).copy()
        ankle = Configuration(model, q).frame_position(human.frame_id(f"{letter}Ankle")).copy()
        q[index] = 0.3
        after = Configuration(model, q)
        moved = after.frame_position(human.frame_id(f"{letter}BigToe")) - before
        assert outwards * moved[2] > 0.03  # toes out by the turn times the foot's length
        assert abs(moved[1]) < 1e-12  # about the vertical shank: the toe keeps its height
        np.testing.assert_allclose(after.frame_position(human.frame_id(f"{letter}Ankle")), ankle, atol=1e-12)


def test_the_foot_rotation_is_added_once_to_a_subject_urdf_written_and_read_back(human, tmp_path):
    from ibik_pin.subject.urdf import write_subject_urdf

    write_subject_urdf(human, tmp_path / "subject.urdf")
    text = (tmp_path / "subject.urdf").read_text()
    assert text.count('name="left_ankle_Y"') == 1 and text.count('name="right_ankle_Y"') == 1
    reloaded = load_human(tmp_path / "subject.urdf")
    assert reloaded.model.nq == human.model.nq
    assert [reloaded.model.names[j] for j in range(reloaded.model.njoints)] == list(human.model.names)


def test_the_human_s_neutral_stature_is_measured_as_documented(human):
    assert neutral_stature(human) == pytest.approx(HUMAN_NEUTRAL_STATURE_M, abs=5e-4)
