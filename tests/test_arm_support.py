"""Tests of an arm's own overlap (tracking.arm_support) and the swivel search reading it."""

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.tasks import ImageTask, View
from ibik_pin.tasks.silhouette_axis import AxisView, SilhouetteAxisTask
from ibik_pin.tracking.arm_support import ARM_CAP, arm_overlap
from ibik_pin.tracking.swivel import SwivelSearch, swivel_circle
from ibik_pin.tracking.trunk import farther_from_axis
from ibik_pin.tracking.views import LIMB_HALF_WIDTH
from ibik_pin.vision.medial_axis import medial_axis_pixels
from ibik_pin.vision.pinhole import look_at_camera
from ibik_pin.vision.render import render_capsules
from ibik_pin.vision.support import support_from_mask

#: The sweep's thinnest bodies: limb radii x0.7 (experiments/sweepkit/conditions.py).
THIN_ARM = 0.7


def _thin_armed_views(human, q, eyes):
    """Image and axis views of the body at q, its arms x THIN_ARM, from cameras at `eyes` (offsets
    from the pelvis [m]), 640 x 480, the support capped at a limb's half width as the tracker's."""
    configuration = Configuration(human.model, q)
    ends = configuration.frame_positions(human.segment_frame_ids.reshape(-1)).reshape(-1, 2, 3)
    radii = np.array([radius * (THIN_ARM if {"LElbow", "RElbow"} & set(segment) else 1.0)
                      for segment, radius in zip(human.segments, human.segment_radii, strict=True)])
    centre = configuration.frame_position(human.frame_id("Hip"))
    image_views, axis_views = [], []
    for index, eye in enumerate(eyes):
        camera = look_at_camera(f"view{index}", (640, 480), 600.0, centre + np.asarray(eye), centre,
                                np.array([0.0, 1.0, 0.0]))
        mask = render_capsules(camera, ends[:, 0], ends[:, 1], radii)
        cap = float(camera.pixel_radius(centre[None], np.array([LIMB_HALF_WIDTH]))[0])
        image_views.append(View(camera, support_from_mask(mask, inside_cap_px=cap)))
        axis_views.append(AxisView(camera, medial_axis_pixels(mask), 8.0))
    return configuration, ImageTask(human, image_views), SilhouetteAxisTask(human, axis_views)


def test_an_arm_over_the_trunk_outscores_a_thin_arm_on_its_own_silhouette_only_below_the_arms_cap(human):
    """The support's one cap rewards an arm laid over the chest more than the true thin arm beside
    the trunk; read no deeper than the arm's cap, both are simply inside."""
    q = pin.neutral(human.model)  # facing +x, Y up, the left arm hanging at z = -0.21
    configuration, image, _ = _thin_armed_views(human, q, [(3.5, 0.3, 0.8), (2.5, 0.4, -2.6)])
    shoulder, elbow, wrist = configuration.frame_positions(human.frame_ids(["LShoulder", "LElbow", "LWrist"]))
    # The same arm laid down the front of the chest (inside the trunk's capsule, radius 0.13 m, in both views).
    over_chest = np.array([[0.06, 0.30, -0.06], [0.08, 0.05, -0.04], [0.06, -0.2, -0.02]])
    assert image.inside_silhouettes(np.concatenate([over_chest, [shoulder, elbow, wrist]])).all()
    roots = np.array([shoulder, over_chest[0]])
    middles = np.array([[elbow], [over_chest[1]]])
    ends = np.array([wrist, over_chest[2]])
    body_cap = arm_overlap(image, roots, middles, ends, cap=LIMB_HALF_WIDTH)[:, 0]
    arm_cap = arm_overlap(image, roots, middles, ends, cap=0.02)[:, 0]
    assert body_cap[1] > 1.2 * body_cap[0]  # the chest reads deeper than the thin arm
    assert arm_cap[1] == pytest.approx(arm_cap[0], rel=0.05)  # both full at the arm's cap


def test_with_the_body_cap_the_arms_overlap_is_the_image_tasks_own_difference_between_swivels(human):
    """arm_overlap reads the image task's samples of the arm: at the support's own cap, two elbow
    placements differ by what the image task's values_at says."""
    q = pin.neutral(human.model)
    q[human.model.joints[human.model.getJointId("left_elbow_Z")].idx_q] = 1.3
    configuration, image, _ = _thin_armed_views(human, q, [(3.5, 0.3, 0.8), (0.8, 0.5, -3.8)])
    ids = human.frame_ids(["LShoulder", "LElbow", "LWrist"])
    shoulder, elbow, wrist = configuration.frame_positions(ids)
    moved = elbow + np.array([0.0, 0.03, -0.05])
    current = configuration.frame_positions(image.frame_ids)
    rows = np.flatnonzero(image.frame_ids == ids[1])
    placed = np.array([elbow, moved])
    task_values = image.values_at_moves(current, image.at_pose(current), [(rows, placed)])[0]
    # A cap far above any depth: the support's own values, as the image task reads them.
    arm = arm_overlap(image, shoulder[None], placed[None], wrist[None], cap=10.0)[0]
    assert arm[1] - arm[0] == pytest.approx(task_values[1] - task_values[0], rel=1e-9, abs=1e-12)


def test_the_arms_cap_leaves_the_knees_hints_and_must_be_a_depth(human):
    q = pin.neutral(human.model)
    for joint, angle in [("left_hip_Z", 0.6), ("left_knee_Z", -1.0), ("left_elbow_Z", 1.3)]:
        q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    configuration, image, axis = _thin_armed_views(human, q, [(3.5, 0.3, 0.8), (0.8, 0.5, -3.8)])
    # The knee and the elbow each swivelled 45 degrees away, their limbs' ends kept.
    wrong = {}
    for name, (root, end) in {"LKnee": ("LHip", "LAnkle"), "LElbow": ("LShoulder", "LWrist")}.items():
        points = configuration.frame_positions(human.frame_ids([root, name, end]))
        wrong[human.frame_id(name)] = swivel_circle(*points, 8)[1]

    class Swivelled:  # the configuration's positions with both joints moved, as the search reads them
        def frame_positions(self, ids):
            positions = configuration.frame_positions(ids).copy()
            for frame_id, point in wrong.items():
                positions[np.asarray(ids) == frame_id] = point
            return positions

    terms = [(image, 1.0), (axis, 1.0)]
    capped = SwivelSearch(human, terms, inside_silhouettes=image.inside_silhouettes, arm_cap=ARM_CAP)
    uncapped = SwivelSearch(human, terms, inside_silhouettes=image.inside_silhouettes)
    hints, earlier = (search.hints(Swivelled(), ["LKnee", "LElbow"]) for search in (capped, uncapped))
    knee = configuration.frame_position(human.frame_id("LKnee"))
    assert np.linalg.norm(hints["LKnee"] - knee) < 0.03
    np.testing.assert_array_equal(hints["LKnee"], earlier["LKnee"])
    elbow = configuration.frame_position(human.frame_id("LElbow"))
    # The elbow, 130 mm off, hinted back (44 mm here; the samples' spacing on a 170-mm circle and
    # the axis term's 8-px scale).
    assert np.linalg.norm(wrong[human.frame_id("LElbow")] - elbow) > 0.12
    assert np.linalg.norm(hints["LElbow"] - elbow) < 0.05
    with pytest.raises(InputError, match="arm_cap"):
        SwivelSearch(human, terms, arm_cap=0.0)


def test_farther_from_the_trunks_axis_compares_each_pair_in_the_section():
    hip, neck = np.zeros(3), np.array([0.0, 0.5, 0.0])
    left, right = np.array([0.0, 0.35, -0.19]), np.array([0.0, 0.35, 0.19])  # facing +x, Y up
    starts = np.array([[0.0, 0.2, -0.2], [0.15, 0.2, 0.0]])
    # Beside the trunk, then 0.1 m farther out; in front of the chest, then the same depth behind
    # it, which counts more with a shallower back (0.6 against 1.2 half shoulder widths).
    ends = np.array([[0.0, 0.2, -0.3], [-0.15, 0.2, 0.0]])
    np.testing.assert_array_equal(farther_from_axis(starts, ends, hip, neck, left, right, (0.75, 1.2, 0.6)),
                                  [True, True])
    np.testing.assert_array_equal(farther_from_axis(ends, starts, hip, neck, left, right, (0.75, 1.2, 0.6)),
                                  [False, False])
