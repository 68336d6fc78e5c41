"""Tests of the swivel search of free elbows and knees."""

import numpy as np
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.tasks import ImageTask, View
from ibik_pin.tasks.segments import SegmentCriterion
from ibik_pin.tasks.silhouette_axis import AxisView, SilhouetteAxisTask
from ibik_pin.tracking.swivel import SwivelSearch, inside_trunk, outside_counts, swivel_circle, trunk_distance
from ibik_pin.vision.medial_axis import medial_axis_pixels
from ibik_pin.vision.pinhole import look_at_camera
from ibik_pin.vision.render import render_capsules
from ibik_pin.vision.support import support_from_mask


def test_the_swivel_circle_keeps_both_distances_and_starts_at_the_joint(rng):
    root, middle, end = rng.normal(size=(3, 3))
    circle = swivel_circle(root, middle, end, 24)
    assert circle.shape == (24, 3)
    np.testing.assert_allclose(circle[0], middle, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(circle - root, axis=1), np.linalg.norm(middle - root), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(circle - end, axis=1), np.linalg.norm(middle - end), rtol=1e-12)
    assert np.ptp(circle, axis=0).max() > 0.1  # the points really go round


def test_the_circles_of_several_limbs_are_each_limbs_circle(rng):
    """Limbs stacked (L, 3) give each limb's circle, a straight or collapsed limb its joint alone."""
    roots, middles, ends = rng.normal(size=(3, 4, 3))
    middles[2] = 0.3 * roots[2] + 0.7 * ends[2]  # on the line between its ends: no circle
    ends[3] = roots[3]  # ends that coincide: no axis
    circles = swivel_circle(roots, middles, ends, 12)
    assert circles.shape == (4, 12, 3)
    for limb in range(2):
        np.testing.assert_allclose(circles[limb], swivel_circle(roots[limb], middles[limb], ends[limb], 12),
                                   rtol=0, atol=1e-14)
        assert np.ptp(circles[limb], axis=0).max() > 0.1
    for limb in (2, 3):
        np.testing.assert_array_equal(circles[limb], np.repeat(middles[limb][None], 12, axis=0))


def _views(human, q):
    configuration = Configuration(human.model, q)
    ends = configuration.frame_positions(human.segment_frame_ids.reshape(-1)).reshape(-1, 2, 3)
    center = configuration.frame_position(human.frame_id("Hip"))
    image_views, axis_views = [], []
    for name, eye in [("front", center + [3.5, 0.3, 0.8]), ("side", center + [0.8, 0.5, -3.8])]:
        camera = look_at_camera(name, (320, 240), 300.0, eye, center, np.array([0.0, 1.0, 0.0]))
        mask = render_capsules(camera, ends[:, 0], ends[:, 1], human.segment_radii)
        image_views.append(View(camera, support_from_mask(mask, inside_cap_px=3.0)))
        axis_views.append(AxisView(camera, medial_axis_pixels(mask), 8.0))
    return image_views, axis_views




def test_the_search_hints_the_elbow_back_toward_the_pose_of_the_silhouette(human):
    import pinocchio as pin

    true_q = pin.neutral(human.model)
    # Left arm raised sideways and bent: an elbow far from the trunk in both views.
    for joint, angle in [("left_shoulder_X", 1.2), ("left_elbow_Z", 1.3)]:
        true_q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    image_views, axis_views = _views(human, true_q)
    image = ImageTask(human, image_views)
    axis = SilhouetteAxisTask(human, axis_views)
    truth = Configuration(human.model, true_q).frame_position(human.frame_id("LElbow")).copy()
    # The same wrist and shoulder, the elbow swivelled 120 degrees away.
    configuration = Configuration(human.model, true_q)
    names = ["LShoulder", "LElbow", "LWrist"]
    shoulder, elbow, wrist = configuration.frame_positions(human.frame_ids(names))
    wrong = swivel_circle(shoulder, elbow, wrist, 3)[1]
    search = SwivelSearch(human, [(image, 1.0), (axis, 1.0)], samples=36)

    class Moved:  # the configuration's positions with the elbow moved, as the search reads them
        def frame_positions(self, ids):
            positions = configuration.frame_positions(ids).copy()
            positions[np.asarray(ids) == human.frame_id("LElbow")] = wrong
            return positions

    hints = search.hints(Moved(), ["LElbow", "RElbow"])
    assert "LElbow" in hints
    assert np.linalg.norm(hints["LElbow"] - truth) < 0.03
    assert np.linalg.norm(wrong - truth) > 0.2
    assert "RElbow" not in hints  # already where its silhouette says


def test_a_limb_whose_ends_leave_the_silhouettes_is_not_searched(human):
    import pinocchio as pin

    true_q = pin.neutral(human.model)
    for joint, angle in [("left_shoulder_X", -1.2), ("left_elbow_Z", 1.3)]:
        true_q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    image_views, axis_views = _views(human, true_q)
    image = ImageTask(human, image_views)
    configuration = Configuration(human.model, true_q)
    shoulder, elbow, wrist = configuration.frame_positions(human.frame_ids(["LShoulder", "LElbow", "LWrist"]))
    assert image.inside_silhouettes(np.array([shoulder, elbow, wrist])).all()
    away = wrist + np.array([0.0, 0.0, 0.5])  # half a metre beside the arm
    assert not image.inside_silhouettes(away[None]).any()
    wrong = swivel_circle(shoulder, elbow, wrist, 3)[1]

    def moved(wrist_at):
        class Moved:  # the elbow swivelled away, the wrist where asked
            def frame_positions(self, ids):
                positions = configuration.frame_positions(ids).copy()
                positions[np.asarray(ids) == human.frame_id("LElbow")] = wrong
                positions[np.asarray(ids) == human.frame_id("LWrist")] = wrist_at
                return positions
        return Moved()

    terms = [(image, 1.0), (SilhouetteAxisTask(human, axis_views), 1.0)]
    trusting = SwivelSearch(human, terms, samples=36, inside_silhouettes=image.inside_silhouettes)
    assert "LElbow" in trusting.hints(moved(wrist), ["LElbow"])
    # A wrist the silhouettes do not show where the target puts it: the views are not trusted,
    # where a search that trusts them still moves the elbow.
    assert trusting.hints(moved(away), ["LElbow"]) == {}
    assert "LElbow" in SwivelSearch(human, terms, samples=36).hints(moved(away), ["LElbow"])


class _Towards:
    """A criterion of the elbow alone: minus its distance to a point [m] (what the search needs)."""

    def __init__(self, human, point):
        self.frame_ids = human.frame_ids(["LElbow"])
        self.point = np.asarray(point)
        self.enabled = True

    def at_pose(self, positions):
        return None

    def values_at(self, positions, moved=None, pose=None):
        return -np.linalg.norm(positions[:, 0] - self.point, axis=1)

    values_at_moves = SegmentCriterion.values_at_moves  # each move through values_at


def _bent_left_arm(human, shoulder_x: float):
    """The neutral pose with the left shoulder raised by `shoulder_x` [rad] and the elbow bent 1.3 rad:
    its configuration and the shoulder, elbow and wrist."""
    import pinocchio as pin

    q = pin.neutral(human.model)
    for joint, angle in [("left_shoulder_X", shoulder_x), ("left_elbow_Z", 1.3)]:
        q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    configuration = Configuration(human.model, q)
    return configuration, configuration.frame_positions(human.frame_ids(["LShoulder", "LElbow", "LWrist"]))


def test_a_hint_needs_every_term_to_agree(human):
    configuration, (shoulder, elbow, wrist) = _bent_left_arm(human, 1.2)
    across = swivel_circle(shoulder, elbow, wrist, 2)[1]  # the far side of the circle
    pulling = _Towards(human, across)
    assert "LElbow" in SwivelSearch(human, [(pulling, 3.0)]).hints(configuration, ["LElbow"])
    # A second term that prefers the joint where it is: the sum still peaks across the circle,
    # but that term would be worse there, so no hint.
    staying = _Towards(human, elbow)
    search = SwivelSearch(human, [(pulling, 3.0), (staying, 1.0)])
    values = 3.0 * pulling.values_at(across[None, None]) + staying.values_at(across[None, None])
    assert values[0] > 3.0 * pulling.values_at(elbow[None, None])[0]  # the sum prefers across
    assert search.hints(configuration, ["LElbow"]) == {}


def test_a_search_needs_three_samples(human):
    with pytest.raises(InputError, match="at least 3"):
        SwivelSearch(human, [], samples=2)


def test_views_cross_only_when_two_optical_axes_are_far_from_parallel():
    from ibik_pin.tracking.swivel import views_cross

    centre, up = np.zeros(3), np.array([0.0, 1.0, 0.0])

    def camera(azimuth_deg):
        azimuth = np.deg2rad(azimuth_deg)
        eye = 4.0 * np.array([np.cos(azimuth), 0.3, np.sin(azimuth)])
        return look_at_camera(f"cam{azimuth_deg}", (64, 48), 50.0, eye, centre, up)

    assert not views_cross([camera(0)])
    assert not views_cross([camera(0), camera(180)])  # facing each other: one line of sight
    assert not views_cross([camera(0), camera(210)])
    assert views_cross([camera(0), camera(90)])
    assert views_cross([camera(0), camera(180), camera(250)])


def test_the_search_reading_each_term_at_the_pose_gives_the_values_of_one_computing_it(human, monkeypatch):
    """Every limb's candidates in one values_at_moves call per term, each term read at the pose once:
    the values values_at gives each limb's candidates computed from scratch (to the bit for the
    silhouette axis; the overlap's moved samples are the pose's shifted, equal within rounding)."""
    import pinocchio as pin

    q = pin.neutral(human.model)
    for joint, angle in [("left_shoulder_X", -1.2), ("left_elbow_Z", 1.3), ("right_shoulder_X", 1.0),
                         ("right_elbow_Z", 1.1), ("left_knee_Z", 0.9), ("right_knee_Z", 0.7)]:
        q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    image_views, axis_views = _views(human, q)
    configuration = Configuration(human.model, q)
    terms = [(ImageTask(human, image_views), 1.0), (SilhouetteAxisTask(human, axis_views), 1.0)]
    search = SwivelSearch(human, terms, samples=36)
    limbs = ["LElbow", "RElbow", "LKnee", "RKnee"]
    answers: list = []  # each term's moves and answers
    for task, _ in terms:
        batched = type(task).values_at_moves.__get__(task)

        def recorded(positions, pose, moves, batched=batched, task=task):
            answers.append((task, positions, moves, batched(positions, pose, moves)))
            return answers[-1][3]

        monkeypatch.setattr(task, "values_at_moves", recorded)
    hints = search.hints(configuration, limbs)
    # Every limb, by both terms, in each pass (the samples, then the finer points around the best).
    assert [len(moves) for _, _, moves, _ in answers] == [len(limbs)] * 4
    assert [len(moves[0][1]) for _, _, moves, _ in answers] == [36, 36, 8, 8]
    for task, positions, moves, values in answers:
        for (rows, placed), mine in zip(moves, values, strict=True):
            candidates = np.repeat(positions[None], len(placed), axis=0)
            candidates[:, rows[0]] = placed
            expected = task.values_at(candidates, moved=rows)
            if isinstance(task, ImageTask):
                np.testing.assert_allclose(mine, expected, rtol=1e-13, atol=1e-13)
            else:
                np.testing.assert_array_equal(mine, expected)  # tolerance 0
    for task, _ in terms:  # the search again, each limb and term computed from scratch
        monkeypatch.setattr(task, "values_at_moves", type(task).values_at_moves.__get__(task))
        monkeypatch.setattr(task, "at_pose", lambda positions: None)
    plain = search.hints(configuration, limbs)
    assert hints.keys() == plain.keys()
    for name in hints:
        np.testing.assert_array_equal(hints[name], plain[name])


def test_both_terms_answer_moves_of_any_size_as_values_at(human, rng):
    """Moves of different candidate counts, one declaring two rows moved (only its first placed):
    each term's batched answer is values_at's for the same candidates."""
    import pinocchio as pin

    q = pin.neutral(human.model)
    for joint, angle in [("left_shoulder_X", -1.2), ("left_elbow_Z", 1.3), ("right_knee_Z", 0.8)]:
        q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    image_views, axis_views = _views(human, q)
    configuration = Configuration(human.model, q)
    for task in (ImageTask(human, image_views), SilhouetteAxisTask(human, axis_views)):
        positions = configuration.frame_positions(task.frame_ids)
        elbow = int(np.flatnonzero(task.frame_ids == human.frame_id("LElbow"))[0])
        knee = int(np.flatnonzero(task.frame_ids == human.frame_id("RKnee"))[0])
        wrist = int(np.flatnonzero(task.frame_ids == human.frame_id("LWrist"))[0])
        moves = [(np.array([elbow]), positions[elbow] + rng.normal(0.0, 0.05, (7, 3))),
                 (np.array([knee]), positions[knee] + rng.normal(0.0, 0.05, (3, 3))),
                 (np.array([elbow, wrist]), positions[elbow] + rng.normal(0.0, 0.05, (5, 3)))]
        answers = task.values_at_moves(positions, task.at_pose(positions), moves)
        assert [len(values) for values in answers] == [7, 3, 5]
        for (rows, placed), values in zip(moves, answers, strict=True):
            candidates = np.repeat(positions[None], len(placed), axis=0)
            candidates[:, rows[0]] = placed
            np.testing.assert_allclose(values, task.values_at(candidates, moved=rows), rtol=1e-13, atol=1e-13)
        assert np.ptp(answers[0]) > 0.0  # the candidates really differ


def test_the_circle_at_given_angles_is_the_circle_of_that_many_even_samples(rng):
    roots, middles, ends = rng.normal(size=(3, 2, 3))
    even = 2.0 * np.pi * np.arange(8) / 8
    np.testing.assert_array_equal(swivel_circle(roots, middles, ends, 8, angles=even),
                                  swivel_circle(roots, middles, ends, 8))
    per_limb = np.array([even[:3], even[5:]])  # each limb its own angles
    circles = swivel_circle(roots, middles, ends, 3, angles=per_limb)
    np.testing.assert_allclose(circles[0], swivel_circle(roots, middles, ends, 8)[0, :3], rtol=0, atol=1e-14)
    np.testing.assert_allclose(circles[1], swivel_circle(roots, middles, ends, 8)[1, 5:], rtol=0, atol=1e-14)


def test_the_second_pass_brings_a_coarse_hint_closer_to_the_pose_of_the_silhouette(human):
    import pinocchio as pin

    true_q = pin.neutral(human.model)
    for joint, angle in [("left_shoulder_X", 1.2), ("left_elbow_Z", 1.3)]:
        true_q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    image_views, axis_views = _views(human, true_q)
    terms = [(ImageTask(human, image_views), 1.0), (SilhouetteAxisTask(human, axis_views), 1.0)]
    truth = Configuration(human.model, true_q).frame_position(human.frame_id("LElbow")).copy()
    configuration = Configuration(human.model, true_q)
    shoulder, elbow, wrist = configuration.frame_positions(human.frame_ids(["LShoulder", "LElbow", "LWrist"]))
    # The elbow swivelled 100 degrees away: 8 samples (45 degrees apart) cannot land on the truth.
    wrong = swivel_circle(shoulder, elbow, wrist, 1, angles=np.array([np.deg2rad(100.0)]))[0]

    class Moved:  # the configuration's positions with the elbow moved, as the search reads them
        def frame_positions(self, ids):
            positions = configuration.frame_positions(ids).copy()
            positions[np.asarray(ids) == human.frame_id("LElbow")] = wrong
            return positions

    coarse = SwivelSearch(human, terms, samples=8, refine=0).hints(Moved(), ["LElbow"])["LElbow"]
    refined = SwivelSearch(human, terms, samples=8, refine=4).hints(Moved(), ["LElbow"])["LElbow"]
    radius = np.linalg.norm(truth - (shoulder + wrist) / 2.0)  # about the circle's, for the scale
    assert np.linalg.norm(coarse - truth) > 0.1 * radius  # 45-degree steps leave it off (30 mm here)
    assert np.linalg.norm(refined - truth) < 0.5 * np.linalg.norm(coarse - truth)  # 3 mm here
    with pytest.raises(InputError, match="refine"):
        SwivelSearch(human, terms, refine=-1)


def test_the_trunk_section_holds_true_poses_outside_and_an_arm_laid_across_the_chest_inside():
    hip, neck = np.zeros(3), np.array([0.0, 0.5, 0.0])
    left, right = np.array([0.0, 0.35, -0.19]), np.array([0.0, 0.35, 0.19])  # facing +x, Y up
    points = np.array([[0.0, 0.2, 0.0],  # the trunk's centre
                       [0.0, 0.2, -0.19],  # below the left shoulder, arm hanging
                       [0.13, 0.2, 0.0],  # in front of the chest, an arm's radius off a 0.1-m half depth
                       [0.05, 0.2, -0.1],  # within the trunk's front half
                       [0.0, -0.05, 0.0],  # below the pelvis centre
                       [0.0, 0.55, 0.0]])  # above the neck
    inside = inside_trunk(points, hip, neck, left, right)
    np.testing.assert_array_equal(inside, [True, False, False, True, False, False])
    # the section's semi-axes are in half shoulder widths: a wider subject, a wider trunk
    assert inside_trunk(np.array([0.0, 0.2, -0.15]), hip, neck, 1.5 * left, 1.5 * right)
    assert not inside_trunk(np.array([0.0, 0.2, -0.15]), hip, neck, left, right)


def test_an_elbow_laid_into_the_trunk_is_hinted_out_even_where_every_term_prefers_it(human):
    import pinocchio as pin

    q = pin.neutral(human.model)
    # The upper arm swung across the chest: the elbow inside the trunk, an impossible pose.
    for joint, angle in [("left_shoulder_X", -1.2), ("left_elbow_Z", 1.3)]:
        q[human.model.joints[human.model.getJointId(joint)].idx_q] = angle
    configuration = Configuration(human.model, q)
    shoulder, elbow, wrist = configuration.frame_positions(human.frame_ids(["LShoulder", "LElbow", "LWrist"]))
    trunk = configuration.frame_positions(human.frame_ids(["Hip", "Neck", "LShoulder", "RShoulder"]))
    assert inside_trunk(elbow, *trunk)
    staying = _Towards(human, elbow)  # a criterion whose peak is where the elbow is
    hints = SwivelSearch(human, [(staying, 1.0)]).hints(configuration, ["LElbow"])
    assert "LElbow" in hints
    assert not inside_trunk(hints["LElbow"], *trunk)
    # the best swivel outside the trunk: the nearest to the elbow on its circle
    circle = swivel_circle(shoulder, elbow, wrist, 360)
    outside = circle[~inside_trunk(circle, *trunk)]
    nearest = outside[np.argmin(np.linalg.norm(outside - elbow, axis=1))]
    assert np.linalg.norm(hints["LElbow"] - nearest) < 0.02
    assert SwivelSearch(human, [(staying, 1.0)], trunk_section=None).hints(configuration, ["LElbow"]) == {}


def test_a_third_semi_axis_gives_the_trunk_section_its_own_front():
    hip, neck = np.zeros(3), np.array([0.0, 0.5, 0.0])
    left, right = np.array([0.0, 0.35, -0.19]), np.array([0.0, 0.35, 0.19])  # facing +x, Y up
    # One half shoulder width (0.19 m) in front of the axis near the middle, and as far behind.
    in_front, behind = np.array([0.19, 0.2, -0.03]), np.array([-0.19, 0.2, -0.03])
    section = (0.75, 1.2, 0.6)
    assert inside_trunk(in_front, hip, neck, left, right, section)
    assert not inside_trunk(behind, hip, neck, left, right, section)
    assert not inside_trunk(in_front, hip, neck, left, right)  # the default pair: 0.6 both ways
    distance, along = trunk_distance(np.stack([in_front, behind]), hip, neck, left, right, section)
    sideways = 0.03 / (0.75 * 0.19)
    np.testing.assert_allclose(distance, [np.hypot(sideways, 1 / 1.2), np.hypot(sideways, 1 / 0.6)], rtol=1e-12)
    np.testing.assert_allclose(along, [0.4, 0.4], rtol=1e-12)


def test_outside_counts_count_each_segments_points_outside():
    roots, ends = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, -0.6, 0.0]])
    middles = np.array([[[0.2, -0.3, 0.0], [-0.2, -0.3, 0.0]]])  # two candidates of one limb

    def left_of_x(points):  # a silhouette: the half-space x < 0.1
        return points[:, 0] < 0.1

    counts = outside_counts(left_of_x, roots, middles, ends, samples=4)
    # Candidate 0: on each segment the points at x = 0.025, 0.075, 0.125, 0.175 -> two outside each.
    np.testing.assert_array_equal(counts, [[4, 0]])
    np.testing.assert_array_equal(outside_counts(left_of_x, roots, middles[:, 0], ends, samples=4), [4])


def _arm_beside_the_trunk(human):
    configuration, (shoulder, elbow, wrist) = _bent_left_arm(human, 0.3)
    trunk = configuration.frame_positions(human.frame_ids(["Hip", "Neck", "LShoulder", "RShoulder"]))
    circle = swivel_circle(shoulder, elbow, wrist, 72)
    distance, _ = trunk_distance(circle, *trunk)
    nearest_trunk = circle[np.argmin(np.where(inside_trunk(circle, *trunk), np.inf, distance))]
    return configuration, (shoulder, elbow, wrist), trunk, nearest_trunk


def test_an_elbow_the_silhouettes_do_not_refute_is_not_hinted_toward_the_trunk(human):
    """Two views' silhouettes cover an arm laid over the trunk as well as one beside it: a criterion
    that prefers the trunk is no evidence while the arm where it is lies inside them."""
    configuration, (_, elbow, _), trunk, nearest_trunk = _arm_beside_the_trunk(human)
    assert trunk_distance(nearest_trunk, *trunk)[0] < trunk_distance(elbow, *trunk)[0] - 0.3
    pulling = [(_Towards(human, nearest_trunk), 1.0)]

    def everywhere(points):
        return np.ones(len(points), dtype=bool)

    assert SwivelSearch(human, pulling, inside_silhouettes=everywhere).hints(configuration, ["LElbow"]) == {}
    earlier = SwivelSearch(human, pulling, inside_silhouettes=everywhere, keep_unrefuted=False)
    assert np.linalg.norm(earlier.hints(configuration, ["LElbow"])["LElbow"] - nearest_trunk) < 0.01


def test_a_refuted_elbow_is_hinted_to_the_nearest_swivel_the_silhouettes_allow(human):
    configuration, (shoulder, elbow, wrist), _, nearest_trunk = _arm_beside_the_trunk(human)
    axis = (wrist - shoulder) / np.linalg.norm(wrist - shoulder)
    centre = shoulder + ((elbow - shoulder) @ axis) * axis
    radius = np.linalg.norm(elbow - centre)
    outward = (elbow - centre) / radius

    def short_of_the_elbow(points):  # a silhouette that ends short of the elbow, 0.8 of the radius out
        return (points - centre) @ outward < 0.8 * radius

    pulling = [(_Towards(human, nearest_trunk), 1.0)]
    search = SwivelSearch(human, pulling, inside_silhouettes=short_of_the_elbow)
    hint = search.hints(configuration, ["LElbow"])["LElbow"]
    assert outside_counts(short_of_the_elbow, shoulder[None], hint[None], wrist[None])[0] == 0
    # The least swivel that clears it: the arm's outermost points (11/12 of each segment) inside
    # once cos(swivel) < 0.8 / (11/12), 29 degrees (a chord of 0.5 radius); the samples are 10
    # degrees apart, then refined. The criterion's peak, nearer the trunk, is not taken.
    assert 0.45 * radius < np.linalg.norm(hint - elbow) < 0.65 * radius
    assert np.linalg.norm(hint - nearest_trunk) > 0.3 * radius
