import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.exceptions import FileFormatError, IbikError, InputError, UnknownNameError
from ibik_pin.model import (
    human_urdf_path,
    load_arm,
    load_human,
    load_leg,
    load_planar_chain,
    load_urdf,
    set_segment_length,
)


def test_the_human_comes_from_the_installed_example_robot_data():
    path = human_urdf_path()
    assert path.name == "human.urdf"
    assert "example-robot-data" in str(path)


def test_the_human_has_36_joints_and_a_free_flyer(human):
    assert human.model.nq == 43
    assert human.model.nv == 42


def test_the_human_loads_without_a_free_flyer_too():
    body = load_human(free_flyer=False)
    assert body.model.nv == 36
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


@pytest.mark.parametrize(
    ("loader", "nq", "end"), [(load_planar_chain, 4, "end_effector"), (load_arm, 6, "Wrist"), (load_leg, 6, "Ankle")]
)
def test_project_models_load_with_their_end_effector(loader, nq, end):
    body = loader()
    assert body.model.nq == nq
    assert body.end_effectors == [end]
    assert np.all(body.model.upperPositionLimit > body.model.lowerPositionLimit)


def test_the_planar_chain_is_one_metre_long():
    body = load_planar_chain()
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, np.zeros(4))
    assert np.allclose(data.oMf[body.frame_id("end_effector")].translation, [1.0, 0.0, 0.0])


def test_an_unknown_keypoint_lists_the_known_ones(human):
    with pytest.raises(UnknownNameError, match="known keypoints: Hip, LHip"):
        human.frame_id("LeftElbow")


def test_a_missing_urdf_is_a_file_format_error(tmp_path):
    with pytest.raises(FileFormatError, match="does not exist"):
        load_urdf(tmp_path / "nope.urdf")


def test_a_broken_urdf_is_a_file_format_error(tmp_path):
    path = tmp_path / "broken.urdf"
    path.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'>")
    with pytest.raises(IbikError, match=r"broken\.urdf"):
        load_urdf(path)


def test_segment_length_scales_the_joint_offset():
    body = load_arm()
    set_segment_length(body.model, "elbow_Z", 0.31)
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, np.zeros(6))
    assert np.isclose(np.linalg.norm(data.oMf[body.frame_id("Elbow")].translation), 0.31)
    with pytest.raises(InputError, match="must be positive"):
        set_segment_length(body.model, "elbow_Z", -1.0)
