"""Tests of the medial axis of a silhouette and of the silhouette-axis criterion."""

import numpy as np
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.synthetic.silhouettes import render_silhouettes
from ibik_pin.tasks import ImageTask, View
from ibik_pin.tasks.silhouette_axis import (
    AxisView,
    SilhouetteAxisTask,
)
from ibik_pin.tasks.weighted_sum import WeightedSum
from ibik_pin.vision.candidate_kernels import candidate_axis_values, nearest_of_rows, segment_squared_distances
from ibik_pin.vision.distance import distance_to_background
from ibik_pin.vision.kernels import axis_value_and_frame_gradient, axis_value_and_pixel_gradient
from ibik_pin.vision.medial_axis import medial_axis_pixels
from ibik_pin.vision.pinhole import look_at_camera
from ibik_pin.vision.render import render_capsules
from ibik_pin.vision.support import support_from_mask
from tests.conftest import central_difference_gradient, random_human_configuration


def test_the_medial_axis_of_a_bar_is_its_centre_line():
    mask = np.zeros((60, 100), bool)
    mask[20:31, 10:90] = True  # rows 20..30: centre row 25
    pixels = medial_axis_pixels(mask, min_depth_px=2.0, spacing_px=1)
    assert len(pixels) > 50
    middle = pixels[(pixels[:, 0] > 20) & (pixels[:, 0] < 80)]
    assert np.all(np.abs(middle[:, 1] - 25.0) <= 0.5)


def test_the_medial_axis_of_an_empty_mask_is_empty_and_bad_masks_are_refused():
    assert medial_axis_pixels(np.zeros((10, 10), bool)).shape == (0, 2)
    with pytest.raises(InputError, match="expected a 2D"):
        medial_axis_pixels(np.zeros((4, 4, 3)))
    with pytest.raises(InputError, match="spacing_px"):
        medial_axis_pixels(np.ones((4, 4)), spacing_px=0)


def test_the_medial_axis_is_thinned_and_capped():
    mask = np.zeros((200, 200), bool)
    mask[50:150, 50:150] = True
    assert len(medial_axis_pixels(mask, spacing_px=1, max_points=40)) == 40
    dense = medial_axis_pixels(mask, spacing_px=1, max_points=10_000)
    sparse = medial_axis_pixels(mask, spacing_px=4, max_points=10_000)
    assert len(sparse) < len(dense) / 2


def _reference_medial_axis(mask, min_depth_px, spacing_px, max_points):
    """The medial axis in plain numpy, as medial_axis_pixels computed it before its compiled loop:
    ridge tests on whole shifted arrays, then one pixel per block by a sort."""
    inside = (mask != 0).astype(np.uint8)
    rows, columns = np.nonzero(inside)
    top, left = rows.min(), columns.min()
    depth = distance_to_background(np.pad(inside[top:rows.max() + 1, left:columns.max() + 1], 1))
    centre = depth[1:-1, 1:-1]
    height, width = centre.shape
    ridge = np.zeros(centre.shape, dtype=bool)
    for row_step, column_step in ((0, 1), (1, 0), (1, 1), (1, -1)):
        before = depth[1 - row_step:1 - row_step + height, 1 - column_step:1 - column_step + width]
        after = depth[1 + row_step:1 + row_step + height, 1 + column_step:1 + column_step + width]
        ridge |= (centre >= before) & (centre > after)
    ridge &= centre >= min_depth_px
    rows, columns = np.nonzero(ridge)
    depths = centre[rows, columns]
    rows, columns = rows + top, columns + left
    blocks = (rows // spacing_px) * ((mask.shape[1] + spacing_px - 1) // spacing_px) + columns // spacing_px
    order = np.lexsort((-depths, blocks))
    first = np.ones(order.size, dtype=bool)
    first[1:] = blocks[order[1:]] != blocks[order[:-1]]
    kept = order[first]
    if kept.size > max_points:
        kept = kept[np.linspace(0, kept.size - 1, max_points).round().astype(int)]
    return np.column_stack((columns[kept], rows[kept])).astype(np.float64)


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_medial_axis_equals_the_plain_one(human, seed):
    """Silhouettes of seeded poses, one cut by the frame's edge, with speckle: the same pixels in
    the same order for every spacing and cap."""
    rng = np.random.default_rng(seed)
    q = random_human_configuration(human, rng, spread=0.5)
    q[:3] = 0.0
    eye = np.array([3.0, 0.4, 1.0]) if seed != 3 else np.array([1.2, 0.4, 0.3])  # seed 3: close, cut by the edge
    camera = look_at_camera("cam", (160, 120), 150.0, eye, np.zeros(3), np.array([0.0, 1.0, 0.0]))
    mask = render_silhouettes(human, q, [camera])[0]
    mask ^= rng.random(mask.shape) < 0.02  # speckle: holes inside, dots outside
    for spacing, cap in ((1, 10_000), (3, 600), (3, 25), (4, 10_000)):
        np.testing.assert_array_equal(medial_axis_pixels(mask, 1.5, spacing, cap),
                                      _reference_medial_axis(mask, 1.5, spacing, cap))


def _axis_views(human, q, scale_px=6.0):
    configuration = Configuration(human.model, q)
    ends = configuration.frame_positions(human.segment_frame_ids.reshape(-1)).reshape(-1, 2, 3)
    center = configuration.frame_position(human.frame_id("Hip"))
    views = []
    for name, eye in [("front", center + [3.5, 0.3, 0.5]), ("side", center + [0.4, 0.5, -3.8])]:
        camera = look_at_camera(name, (320, 240), 300.0, eye, center, np.array([0.0, 1.0, 0.0]))
        mask = render_capsules(camera, ends[:, 0], ends[:, 1], human.segment_radii)
        views.append((camera, mask, AxisView(camera, medial_axis_pixels(mask), scale_px)))
    return views


def test_the_axis_gradient_matches_finite_differences_on_the_human_with_two_cameras(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    q = random_human_configuration(human, rng, spread=0.3)
    q[:7] = silhouette_q[:7]
    task = SilhouetteAxisTask(human, [view for _, _, view in _axis_views(human, silhouette_q)])
    analytic = task.compute_gradient(Configuration(human.model, q))
    # The criterion is piecewise smooth (a sample changes nearest segment, a closest point reaches a
    # segment's end); a segment seen end-on (the hips from the side) packs those kinks close together,
    # so the difference step must be small enough not to straddle one.
    numeric = central_difference_gradient(task, human.model, q, eps=1e-7)
    assert np.linalg.norm(analytic) > 0.0
    assert np.linalg.norm(numeric - analytic) / np.linalg.norm(analytic) <= 1e-4


def test_the_axis_criterion_is_highest_at_the_pose_that_made_the_silhouette(human, rng):
    true_q = random_human_configuration(human, rng, spread=0.3)
    task = SilhouetteAxisTask(human, [view for _, _, view in _axis_views(human, true_q)])
    at_truth = task.compute_value(Configuration(human.model, true_q))
    for _ in range(5):
        other = random_human_configuration(human, rng, spread=0.3)
        other[:7] = true_q[:7]
        assert task.compute_value(Configuration(human.model, other)) < at_truth


def test_the_weighted_sum_adds_values_and_gradients(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    q = random_human_configuration(human, rng, spread=0.3)
    q[:7] = silhouette_q[:7]
    views = _axis_views(human, silhouette_q)
    image = ImageTask(human, [View(camera, support_from_mask(mask, inside_cap_px=4.0)) for camera, mask, _ in views])
    axis = SilhouetteAxisTask(human, [view for _, _, view in views])
    both = WeightedSum([image, axis], [1.0, 2.0])
    configuration = Configuration(human.model, q)
    assert both.compute_value(configuration) == pytest.approx(
        image.compute_value(configuration) + 2.0 * axis.compute_value(configuration), rel=1e-12)
    np.testing.assert_allclose(both.compute_gradient(configuration),
                               image.compute_gradient(configuration) + 2.0 * axis.compute_gradient(configuration),
                               rtol=1e-12, atol=1e-15)
    axis.set_views([])
    assert both.enabled and not axis.enabled
    with pytest.raises(InputError, match="one weight per term"):
        WeightedSum([image, axis], [1.0])
    with pytest.raises(InputError, match="non-negative"):
        WeightedSum([image], [-1.0])


def test_values_at_candidates_equal_the_criteria_at_the_configurations(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    views = _axis_views(human, silhouette_q)
    image = ImageTask(human, [View(camera, support_from_mask(mask, inside_cap_px=4.0)) for camera, mask, _ in views])
    axis = SilhouetteAxisTask(human, [view for _, _, view in views])
    configurations = []
    for _ in range(3):
        q = random_human_configuration(human, rng, spread=0.3)
        q[:7] = silhouette_q[:7]
        configurations.append(Configuration(human.model, q))
    for task in (image, axis):
        batch = np.stack([c.frame_positions(task.frame_ids) for c in configurations])
        np.testing.assert_allclose(task.values_at(batch), [task.compute_value(c) for c in configurations],
                                   rtol=1e-10, atol=1e-12)


def test_values_at_with_the_moved_frames_named_equals_the_full_evaluation(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    axis = SilhouetteAxisTask(human, [view for _, _, view in _axis_views(human, silhouette_q)])
    positions = np.repeat(Configuration(human.model, silhouette_q).frame_positions(axis.frame_ids)[None], 5, axis=0)
    row = int(np.flatnonzero(axis.frame_ids == human.frame_id("LElbow"))[0])
    positions[:, row] += rng.normal(0.0, 0.05, (5, 3))
    np.testing.assert_allclose(axis.values_at(positions, moved=np.array([row])), axis.values_at(positions),
                               rtol=1e-12, atol=1e-12)


def test_the_image_values_at_with_the_moved_frames_named_equal_the_full_evaluation(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    views = _axis_views(human, silhouette_q)
    image = ImageTask(human, [View(camera, support_from_mask(mask, inside_cap_px=4.0)) for camera, mask, _ in views])
    positions = np.repeat(Configuration(human.model, silhouette_q).frame_positions(image.frame_ids)[None], 5, axis=0)
    row = int(np.flatnonzero(image.frame_ids == human.frame_id("RKnee"))[0])
    positions[:, row] += rng.normal(0.0, 0.05, (5, 3))
    np.testing.assert_allclose(image.values_at(positions, moved=np.array([row])), image.values_at(positions),
                               rtol=1e-12, atol=1e-12)



def _plain_closest(sample, a, b):
    """The closest point's parameter s on segment a-b and the residual sample - closest point."""
    along = b - a
    s = float(np.clip((sample - a) @ along / max(along @ along, 1e-12), 0.0, 1.0))
    return s, sample - (a + s * along)


def _plain_axis_term(samples, end_pixels, start_index, end_index, scale):
    """The axis term of one view and its pixel gradient, sample by sample and segment by segment."""
    value, gradient = 0.0, np.zeros_like(end_pixels)
    for sample in samples:
        closest = [_plain_closest(sample, end_pixels[a], end_pixels[b]) for a, b in zip(start_index, end_index,
                                                                                       strict=True)]
        segment = int(np.argmin([residual @ residual for _, residual in closest]))
        s, residual = closest[segment]
        weight = np.exp(-(residual @ residual) / scale**2)
        value -= 0.5 * scale * (1.0 - weight) / len(samples)
        pull = weight / (scale * len(samples)) * residual
        gradient[start_index[segment]] += (1.0 - s) * pull
        gradient[end_index[segment]] += s * pull
    return value, gradient


def test_the_compiled_axis_term_and_the_vectorised_distances_equal_the_plain_ones(human, rng):
    """The compiled term and its gradient, and the candidates' nearest distances in (C, S, N),
    against Python loops over samples and segments, on seeded problems."""
    task = SilhouetteAxisTask(human)
    frames = len(task.frame_ids)
    for _ in range(5):
        samples = rng.uniform(0.0, 320.0, (40, 2))
        end_pixels = rng.uniform(0.0, 320.0, (frames, 2))
        end_pixels[task._end_index[0]] = end_pixels[task._start_index[0]]  # a segment of zero length
        gradient = np.zeros_like(end_pixels)
        value = axis_value_and_pixel_gradient(samples, end_pixels, task._start_index, task._end_index, 15.0,
                                              gradient)
        plain_value, plain_gradient = _plain_axis_term(samples, end_pixels, task._start_index,
                                                       task._end_index, 15.0)
        np.testing.assert_allclose(value, plain_value, rtol=1e-12)
        np.testing.assert_allclose(gradient, plain_gradient, rtol=1e-10, atol=1e-15)
        starts, ends = rng.uniform(0.0, 320.0, (2, 7, 3, 2))  # 7 candidates, 3 segments each
        plain = np.array([[min(float(residual @ residual) for _, residual in
                               (_plain_closest(sample, a[k], b[k]) for k in range(3))) for sample in samples]
                          for a, b in zip(starts, ends, strict=True)])
        values = np.empty(7)
        candidate_axis_values(samples, starts, ends, np.full(len(samples), np.inf), 15.0, values)
        np.testing.assert_allclose(values, _robust_values(plain, 15.0), rtol=1e-12)


def test_the_axis_terms_world_gradient_is_its_pixel_gradient_through_the_projection(human, rng):
    """dh/dX of the ends = dh/d pixels . d pixels/dX; an end behind the camera leaves the view out."""
    task = SilhouetteAxisTask(human)
    frames = len(task.frame_ids)
    samples = rng.uniform(0.0, 320.0, (60, 2))
    end_pixels = rng.uniform(0.0, 320.0, (frames, 2))
    jacobians = rng.normal(size=(frames, 2, 3))
    pixel_gradient = np.zeros_like(end_pixels)
    expected_value = axis_value_and_pixel_gradient(samples, end_pixels, task._start_index, task._end_index, 15.0,
                                                   pixel_gradient)
    frame_gradient = np.ones((frames, 3))  # added to
    value, in_front = axis_value_and_frame_gradient(samples, end_pixels, jacobians, np.full(frames, 2.0),
                                                    task._start_index, task._end_index, 15.0, frame_gradient)
    assert in_front and value == expected_value
    np.testing.assert_allclose(frame_gradient - 1.0, np.einsum("ki,kij->kj", pixel_gradient, jacobians),
                               rtol=0, atol=1e-15)
    depth = np.full(frames, 2.0)
    depth[3] = 0.0
    untouched = np.ones((frames, 3))
    assert axis_value_and_frame_gradient(samples, end_pixels, jacobians, depth, task._start_index,
                                         task._end_index, 15.0, untouched) == (0.0, False)
    assert (untouched == 1.0).all()


def test_the_compiled_segment_distances_and_their_nearest_equal_the_plain_ones(rng):
    samples = rng.uniform(0.0, 320.0, (50, 2))
    starts, ends = rng.uniform(0.0, 320.0, (2, 6, 2))
    ends[2] = starts[2]  # a segment of zero length
    distances = np.empty((6, 50))
    segment_squared_distances(samples, starts, ends, distances)
    plain = np.array([[float(residual @ residual) for _, residual in
                       (_plain_closest(sample, a, b) for sample in samples)]
                      for a, b in zip(starts, ends, strict=True)])
    np.testing.assert_allclose(distances, plain, rtol=1e-12, atol=1e-9)
    nearest = np.empty(50)
    nearest_of_rows(distances, np.array([1, 4, 5]), nearest)
    np.testing.assert_array_equal(nearest, distances[[1, 4, 5]].min(axis=0))
    nearest_of_rows(distances, np.zeros(0, dtype=np.int64), nearest)
    assert np.isinf(nearest).all()  # no shared segment: nothing is near


def _robust_values(squared_distances, scale):
    """Per candidate (row), the axis term of its samples' squared distances [px^2]."""
    return -0.5 * scale * np.mean(1.0 - np.exp(-squared_distances / scale**2), axis=1)


def test_the_candidates_axis_values_with_shared_segments_read_the_smaller_distance(rng):
    """Samples far from every candidate's segments take the shared segments' distance, read once
    for all candidates (most of them here: the candidates move in a small box)."""
    for _ in range(20):
        samples = rng.uniform(0.0, 640.0, (300, 2))
        starts, ends = rng.uniform(250.0, 330.0, (2, 36, 2, 2))  # 36 candidates of 2 moving segments
        fixed = np.min([[float(residual @ residual) for sample in samples
                         for residual in [_plain_closest(sample, a, b)[1]]]
                        for a, b in rng.uniform(0.0, 640.0, (6, 2, 2))], axis=0)
        plain = np.array([[min(fixed[i], *(float(residual @ residual) for _, residual in
                                           (_plain_closest(sample, a[k], b[k]) for k in range(2))))
                           for i, sample in enumerate(samples)] for a, b in zip(starts, ends, strict=True)])
        values = np.empty(36)
        candidate_axis_values(samples, starts, ends, fixed, 40.0, values)
        np.testing.assert_allclose(values, _robust_values(plain, 40.0), rtol=1e-12)


def test_values_at_reading_the_pose_equal_those_computing_it_for_every_limb(human, rng):
    """The swivel search's use: one pose, each limb's middle joint moved in turn, the first
    candidate a rounding away from the pose (swivel_circle's angle 0)."""
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    views = _axis_views(human, silhouette_q)
    image = ImageTask(human, [View(camera, support_from_mask(mask, inside_cap_px=4.0)) for camera, mask, _ in views])
    axis = SilhouetteAxisTask(human, [view for _, _, view in views])
    q = random_human_configuration(human, rng, spread=0.3)
    q[:7] = silhouette_q[:7]
    configuration = Configuration(human.model, q)
    for task in (image, axis):
        current = configuration.frame_positions(task.frame_ids)
        pose = task.at_pose(current)
        for joint in ("LElbow", "RElbow", "LKnee", "RKnee"):
            row = np.flatnonzero(task.frame_ids == human.frame_id(joint))
            positions = np.repeat(current[None], 36, axis=0)
            positions[:, row[0]] += rng.normal(0.0, 0.05, (36, 3))
            positions[0, row[0]] = current[row[0]] * (1.0 + 2.0**-52)
            np.testing.assert_array_equal(task.values_at(positions, moved=row, pose=pose),
                                          task.values_at(positions, moved=row))  # tolerance 0: the same bits


def test_the_terms_projecting_every_view_together_equal_one_camera_at_a_time(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    views = _axis_views(human, silhouette_q)
    q = random_human_configuration(human, rng, spread=0.3)
    q[:7] = silhouette_q[:7]
    answers = []
    for together in (True, False):
        image = ImageTask(human, [View(camera, support_from_mask(mask, inside_cap_px=4.0))
                                  for camera, mask, _ in views])
        axis = SilhouetteAxisTask(human, [view for _, _, view in views])
        answer = []
        for task in (image, axis):
            if not together:
                task._project = lambda points, task=task: [view.camera.project_with_jacobian(points)
                                                           for view in task._active_views]
            configuration = Configuration(human.model, q)
            current = configuration.frame_positions(task.frame_ids)
            row = np.flatnonzero(task.frame_ids == human.frame_id("RElbow"))
            positions = np.repeat(current[None], 12, axis=0)
            positions[:, row[0]] += np.random.default_rng(5).normal(0.0, 0.05, (12, 3))
            answer += [task.compute_value(configuration), task.compute_gradient(configuration),
                       task.values_at(positions), task.values_at(positions, moved=row),
                       task.values_at(positions, moved=row, pose=task.at_pose(current))]
        answer.append(image.inside_silhouettes(current))
        answers.append(answer)
    for mine, reference in zip(*answers, strict=True):
        np.testing.assert_array_equal(mine, reference)  # tolerance 0: the same bits
