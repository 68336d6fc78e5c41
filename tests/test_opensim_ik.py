"""OpenSim's inverse kinematics on what `ibik track` writes: model.osim fitted to joints.trc finds
motion.mot again, because every body has markers that determine it (virtual ones where the
joint-centre keypoints leave a body free to turn)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ibik_pin.cli import main
from ibik_pin.human import load_human, with_hip_at_hip_joints_midpoint
from ibik_pin.io.osim import VIRTUAL_MARKER_OFFSET_M, virtual_marker_positions, virtual_markers
from tests.opensim_ik import opensim_ik_rms_deg, worst_beyond_tolerance
from tests.paths import TEST_DATA

POSE2SIM_TRC = TEST_DATA / "pose2sim_balancing_excerpt.trc"


def test_a_pelvis_known_by_its_hip_centres_and_their_midpoint_gets_virtual_markers():
    human = load_human()
    on_midpoint = {marker.name for marker in virtual_markers(with_hip_at_hip_joints_midpoint(human))}
    above = {marker.name for marker in virtual_markers(human)}  # the model's Hip sits above the hip line
    assert {"pelvis_axis_x", "pelvis_axis_z"} <= on_midpoint and not any(n.startswith("pelvis") for n in above)


def test_limbs_free_to_turn_about_their_keypoints_get_virtual_markers_and_determined_ones_none():
    names = {marker.name for marker in virtual_markers(load_human())}
    # A thigh known by hip and knee turns about that line; an elbow's pronation moves no keypoint;
    # the trunk segments between pelvis and neck hold none.
    for body in ("left_hip", "right_hip", "left_elbow", "middle_lumbar", "middle_thoracic"):
        assert {f"{body}_axis_x", f"{body}_axis_z"} <= names, body
    # A knee's one rotation moves the ankle; an ankle's three move heel and toes.
    assert not any(name.startswith(("left_knee", "right_knee", "left_ankle", "right_ankle")) for name in names)


def test_virtual_markers_sit_at_their_offset_on_their_body():
    human = load_human()
    markers = virtual_markers(human)
    rng = np.random.default_rng(2)
    q = pin.integrate(human.model, pin.neutral(human.model), 0.5 * rng.normal(size=human.model.nv))
    positions = virtual_marker_positions(human, markers, q[None])[0]
    data = human.model.createData()
    pin.forwardKinematics(human.model, data, q)
    for marker, position in zip(markers, positions, strict=True):
        origin = data.oMi[marker.joint_id].translation
        assert abs(np.linalg.norm(position - origin) - VIRTUAL_MARKER_OFFSET_M) < 1e-12


def test_opensim_ik_on_joints_trc_of_a_trc_run_finds_motion_mot(tmp_path):
    """Pose2Sim's TRC has no Hip: joints.trc's Hip is the hip midpoint, the pelvis' three keypoints
    collinear (OpenSim's fit was 10 degrees off on middle_lumbar_Z without virtual markers)."""
    out = tmp_path / "out"
    assert main(["track", "--targets", str(POSE2SIM_TRC), "--no-image", "--quiet", "--out", str(out)]) == 0
    rms = opensim_ik_rms_deg(out, tmp_path)
    assert worst_beyond_tolerance(rms) == []
    assert len(rms) == 44 and max(rms.values()) > 0.0  # every coordinate compared, from a real fit
