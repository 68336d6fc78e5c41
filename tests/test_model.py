import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.exceptions import FileFormatError, IbikError, InputError, UnknownNameError
from ibik_pin.model import load_arm, load_leg, load_planar_chain, load_urdf, set_segment_length


def test_the_limbs_of_the_human_are_its_arms_and_legs(human):
    model = human.model
    limbs = human.limb_coordinates
    not_limbs = {model.names[j] for j in range(1, model.njoints) if not limbs[model.joints[j].idx_v]}
    assert not_limbs == {"root_joint", "middle_lumbar_Z", "middle_lumbar_X", "middle_thoracic_Z", "middle_thoracic_X",
                         "middle_thoracic_Y", "left_clavicle_joint_X", "right_clavicle_joint_X",
                         "middle_cervical_Z", "middle_cervical_X", "middle_cervical_Y"}
    assert limbs.sum() == 28  # 2 x (3 shoulder + 2 elbow + 2 wrist) + 2 x (3 hip + 1 knee + 3 ankle)
    assert load_arm().limb_coordinates.all()


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
