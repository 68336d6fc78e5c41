"""The compiled loops of the image criteria against the plain numpy reading they replace."""

import numpy as np
import pytest

from ibik_pin.tasks.image import View, support_at
from ibik_pin.vision.camera import OrthographicCamera
from ibik_pin.vision.kernels import pinhole_overlap_at_segments, support_overlap_at_segments
from ibik_pin.vision.pinhole import PinholeCamera
from ibik_pin.vision.support import SupportImage, support_from_mask


def distorted_camera(rng) -> PinholeCamera:
    intrinsics = np.array([[rng.uniform(500, 900), 0.0, rng.uniform(300, 340)],
                           [0.0, rng.uniform(500, 900), rng.uniform(220, 260)], [0.0, 0.0, 1.0]])
    return PinholeCamera.from_rodrigues("cam", (640, 480), intrinsics, [-0.2, 0.05, 0.001, -0.002, 0.01],
                                        rng.normal(0.0, 0.1, 3), [0.0, 0.0, 4.0] + rng.normal(0.0, 0.2, 3))


def silhouette_support() -> SupportImage:
    mask = np.zeros((480, 640), bool)
    mask[150:330, 280:360] = True
    mask[200:230, 200:440] = True
    return support_from_mask(mask)


def plain_reading(projection, support: SupportImage) -> tuple[np.ndarray, np.ndarray]:
    """The support at the points in front (0 behind) and each point's d support / d X_world, by
    SupportImage.sample and the chain rule."""
    in_front = projection.depth > 1e-6
    pixels = np.where(in_front[:, None], projection.pixels, 0.0)  # NaN pixels behind are not read
    sample = support.sample(pixels)
    gradient = np.einsum("mi,mij->mj", sample.gradient, projection.jacobian)
    return np.where(in_front, sample.values, 0.0), np.where(in_front[:, None], gradient, 0.0)


def compiled_overlap(projection, support: SupportImage, whole_frame: bool = False):
    """The compiled overlap's sum, gradient and completeness on the support's held values, each
    point a segment of its own (both ends the point, s = 0)."""
    count = len(projection.depth)
    gradient = np.zeros((count, 3))
    values, row, column = support.held_values(whole_frame)
    own = np.arange(count)
    total, complete = support_overlap_at_segments(*projection, values, row, column, *support.size, own, own,
                                                  np.zeros(count), gradient)
    return total, gradient, complete


def points_around(camera: PinholeCamera, rng, count: int) -> np.ndarray:
    """Points in front of the camera, some projecting outside the image, one behind it and one on
    its focal plane."""
    points = camera.center_world + rng.uniform(2.5, 4.5, (count, 1)) * camera.rotation[2]
    points += rng.normal(0.0, 1.0, (count, 2)) @ camera.rotation[:2]  # sideways: some outside the image
    points[0] = camera.center_world - camera.rotation[2]  # behind
    points[1] = camera.center_world + camera.rotation[0]  # on the focal plane: depth 0
    return points


def test_the_compiled_overlap_equals_the_plain_reading_on_the_whole_frame(rng):
    support = SupportImage(silhouette_support().values)
    for _ in range(5):
        camera = distorted_camera(rng)
        points = points_around(camera, rng, 150)
        projection = camera.project_with_jacobian(points)
        total, gradient, complete = compiled_overlap(projection, support)
        values, expected_gradient = plain_reading(projection, support)
        assert complete
        assert total == pytest.approx(values.sum(), rel=1e-12)
        np.testing.assert_allclose(gradient, expected_gradient, rtol=1e-10, atol=1e-12)
        assert not gradient[:2].any()  # behind the camera and on its plane: no pull
        np.testing.assert_allclose(support_at(View(camera, support), points), values, rtol=1e-12, atol=1e-12)


def test_the_compiled_overlap_on_the_window_is_complete_only_when_every_point_reads_inside_it(rng):
    support = silhouette_support()
    camera = distorted_camera(rng)
    window, row, column = support.held_values()
    assert window.shape != (480, 640) and (row, column) != (0, 0)
    # Points whose pixels lie on the silhouette: read on the window, the whole frame's values.
    rays = np.column_stack([rng.uniform(290, 350, 60), rng.uniform(160, 320, 60)])
    undistorted = np.linalg.solve(camera.intrinsics, np.column_stack([rays, np.ones(60)]).T).T
    points = camera.center_world + (3.0 * undistorted) @ camera.rotation
    projection = camera.project_with_jacobian(points)
    total, gradient, complete = compiled_overlap(projection, support)
    values, expected_gradient = plain_reading(projection, SupportImage(support.values))
    assert complete and total == pytest.approx(values.sum(), rel=1e-12)
    np.testing.assert_allclose(gradient, expected_gradient, rtol=1e-10, atol=1e-12)
    far = np.vstack([points, camera.center_world + 3.0 * camera.rotation[2] + 2.0 * camera.rotation[0]])
    _, untouched, complete = compiled_overlap(camera.project_with_jacobian(far), silhouette_support())
    assert not complete and not untouched.any()  # an incomplete read adds nothing
    # support_at then reads the whole frame.
    windowed = silhouette_support()
    expected, _ = plain_reading(camera.project_with_jacobian(far), SupportImage(windowed.values))
    np.testing.assert_allclose(support_at(View(camera, silhouette_support()), far), expected, rtol=1e-12, atol=1e-12)


def test_the_compiled_overlap_of_an_orthographic_camera_equals_the_plain_reading(rng):
    support = SupportImage(silhouette_support().values)
    camera = OrthographicCamera("ortho", (640, 480), np.eye(3), np.zeros(3), 100.0, np.array([320.0, 240.0]))
    projection = camera.project_with_jacobian(rng.normal(0.0, 1.5, (120, 3)))
    total, gradient, complete = compiled_overlap(projection, support)
    values, expected_gradient = plain_reading(projection, support)
    assert complete and total == pytest.approx(values.sum(), rel=1e-12)
    np.testing.assert_allclose(gradient, expected_gradient, rtol=1e-10, atol=1e-12)


def test_a_samples_pull_goes_to_its_segments_ends_in_proportion(rng):
    """Samples p = (1 - s) X_a + s X_b: the ends' gradient is the interpolation's transpose applied
    to the samples' own gradients."""
    support = SupportImage(silhouette_support().values)
    camera = distorted_camera(rng)
    points = points_around(camera, rng, 80)
    projection = camera.project_with_jacobian(points)
    _, point_gradient, _ = compiled_overlap(projection, support)
    frames = 9
    start, end = rng.integers(0, frames, 80), rng.integers(0, frames, 80)
    fraction = rng.uniform(0.0, 1.0, 80)
    interpolation = np.zeros((80, frames))
    np.add.at(interpolation, (np.arange(80), start), 1.0 - fraction)
    np.add.at(interpolation, (np.arange(80), end), fraction)
    values, row, column = support.held_values()
    frame_gradient = np.zeros((frames, 3))
    total, complete = support_overlap_at_segments(*projection, values, row, column, *support.size, start, end,
                                                  fraction, frame_gradient)
    assert complete and total == pytest.approx(plain_reading(projection, support)[0].sum(), rel=1e-12)
    np.testing.assert_allclose(frame_gradient, interpolation.T @ point_gradient, rtol=1e-10, atol=1e-12)


def test_the_pinhole_overlap_places_and_projects_the_samples_as_the_plain_path_does(rng):
    """Samples placed from the frames' positions (model frames picked by frame_ids) and projected
    in the compiled call: the product's samples projected by the camera and read, within rounding;
    on the window, a sample outside it makes the read incomplete and adds nothing."""
    camera = distorted_camera(rng)
    model_frames, ends = 14, 9
    frame_ids = rng.permutation(model_frames)[:ends]
    completes = []
    for support, whole_frame in ((SupportImage(silhouette_support().values), False), (silhouette_support(), False),
                                 (silhouette_support(), True)):
        positions = np.zeros((model_frames, 3))
        positions[frame_ids] = points_around(camera, rng, ends)
        positions[frame_ids[2:]] = camera.center_world + 3.0 * camera.rotation[2] + rng.normal(0.0, 0.2, (ends - 2, 3))
        start, end = rng.integers(0, ends, 80), rng.integers(0, ends, 80)
        fraction = rng.uniform(0.0, 1.0, 80)
        weights = fraction[:, None]
        samples = (1.0 - weights) * positions[frame_ids[start]] + weights * positions[frame_ids[end]]
        values, row, column = support.held_values(whole_frame)
        expected_gradient = np.zeros((ends, 3))
        expected, expected_complete = support_overlap_at_segments(
            *camera.project_with_jacobian(samples), values, row, column, *support.size, start, end, fraction,
            expected_gradient)
        frame_gradient = np.zeros((ends, 3))
        total, complete = pinhole_overlap_at_segments(positions, frame_ids, start, end, fraction,
                                                      camera.kernel_parameters, values, row, column, *support.size,
                                                      frame_gradient)
        assert complete == expected_complete
        assert total == pytest.approx(expected, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(frame_gradient, expected_gradient, rtol=1e-10, atol=1e-12)
        completes.append(complete)
    assert completes == [True, False, True]  # the window alone misses the samples far out


def test_a_nan_pixel_reads_nothing_and_pulls_nowhere():
    support = SupportImage(silhouette_support().values)
    pixels = np.array([[320.0, 240.0], [np.nan, 240.0], [300.0, np.nan]])
    jacobians = np.ones((3, 2, 3))
    gradient = np.zeros((3, 3))
    values, row, column = support.held_values()
    total, complete = support_overlap_at_segments(pixels, jacobians, np.ones(3), values, row, column, 640, 480,
                                                  np.arange(3), np.arange(3), np.zeros(3), gradient)
    assert complete and total == pytest.approx(float(support.sample(pixels[:1]).values[0]), rel=1e-12)
    assert np.isfinite(gradient).all() and not gradient[1:].any()


def test_the_compiled_finiteness_check_is_numpys(rng):
    """On the arrays the solver checks at every step: rows (2D, C and Fortran order, a slice), q."""
    from ibik_pin.checks import all_finite

    rows = rng.normal(size=(21, 44))
    cases = [rows, np.asfortranarray(rows), rows[:, ::3], rng.normal(size=51), np.zeros((0, 44))]
    for bad in (np.nan, np.inf, -np.inf):
        for case in (rows.copy(), rng.normal(size=51)):
            case.flat[7] = bad
            cases.append(case)
    answers = [all_finite(case) for case in cases]
    assert answers == [bool(np.isfinite(case).all()) for case in cases]
    assert answers.count(True) == 5
