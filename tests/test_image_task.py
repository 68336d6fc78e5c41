import warnings

import numpy as np
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import EmptySilhouetteWarning, InputError
from ibik_pin.synthetic.planar import make_scene, render_chain
from ibik_pin.tasks import ImageTask, View
from ibik_pin.vision.pinhole import look_at_camera
from ibik_pin.vision.render import render_capsules
from ibik_pin.vision.support import SupportImage, support_from_mask
from tests.conftest import central_difference_gradient, random_human_configuration


def smooth_support(mask, sigma_px):
    """A smooth support: the signed distance without cap, blurred wide."""
    return support_from_mask(mask, inside_cap_px=None, smooth_sigma_px=sigma_px)


def test_the_criterion_gradient_matches_finite_differences_on_the_planar_chain():
    scene = make_scene(np.array([0.9, -0.7, -0.6, 0.5]))
    support = smooth_support(scene.silhouette, 4.0)
    task = ImageTask(scene.body, [View(scene.camera, support)], samples_per_segment=10)
    q = np.array([0.4, 0.3, -0.9, 0.7])
    analytic = task.compute_gradient(Configuration(scene.body.model, q))
    numeric = central_difference_gradient(task, scene.body.model, q)
    assert np.linalg.norm(numeric - analytic) / np.linalg.norm(analytic) <= 1e-4


def human_views(human, q):
    """Two cameras around the posed human, each with a smooth support of its rendered silhouette."""
    configuration = Configuration(human.model, q)
    ends = configuration.frame_positions(human.segment_frame_ids.reshape(-1)).reshape(-1, 2, 3)
    center = configuration.frame_position(human.frame_id("Hip"))
    views = []
    for name, eye in [("front", center + [3.5, 0.3, 0.5]), ("side", center + [0.4, 0.5, -3.8])]:
        camera = look_at_camera(name, (320, 240), 300.0, eye, center, np.array([0.0, 1.0, 0.0]))
        mask = render_capsules(camera, ends[:, 0], ends[:, 1], human.segment_radii)
        views.append(View(camera, smooth_support(mask, 3.0)))
    return views


def test_the_criterion_gradient_matches_finite_differences_on_the_human_with_two_cameras(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    q = random_human_configuration(human, rng, spread=0.3)
    q[:7] = silhouette_q[:7]
    task = ImageTask(human, human_views(human, silhouette_q), samples_per_segment=6)
    analytic = task.compute_gradient(Configuration(human.model, q))
    numeric = central_difference_gradient(task, human.model, q)
    assert analytic.shape == (44,)
    assert np.linalg.norm(numeric - analytic) / np.linalg.norm(analytic) <= 1e-4


def test_the_objective_pose_overlaps_better_than_another(human, rng):
    silhouette_q = random_human_configuration(human, rng, spread=0.3)
    task = ImageTask(human, human_views(human, silhouette_q))
    other = random_human_configuration(human, rng, spread=0.3)
    other[:7] = silhouette_q[:7]
    assert task.compute_value(Configuration(human.model, silhouette_q)) > task.compute_value(
        Configuration(human.model, other)
    )


def test_an_empty_silhouette_disables_its_view_with_a_warning():
    scene = make_scene(np.zeros(4))
    with pytest.warns(EmptySilhouetteWarning):
        empty = support_from_mask(np.zeros((400, 400), dtype=bool))
    with pytest.warns(EmptySilhouetteWarning, match="image term is disabled for this view"):
        task = ImageTask(scene.body, [View(scene.camera, empty), View(scene.camera, scene.support)])
    assert task.enabled
    configuration = Configuration(scene.body.model, np.zeros(4))
    only_full = ImageTask(scene.body, [View(scene.camera, scene.support)])
    assert task.compute_value(configuration) == pytest.approx(only_full.compute_value(configuration))


def test_all_views_empty_disables_the_task_without_crashing():
    scene = make_scene(np.zeros(4))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EmptySilhouetteWarning)
        empty = support_from_mask(np.zeros((400, 400), dtype=bool))
        task = ImageTask(scene.body, [View(scene.camera, empty)])
    assert not task.enabled


def test_a_support_whose_size_differs_from_the_camera_is_refused():
    scene = make_scene(np.zeros(4))
    small = SupportImage(np.zeros((240, 320), dtype=np.float32))
    with pytest.raises(InputError, match=r"camera 'virtual': the support image \(mask\) is 320 x 240 px"):
        View(scene.camera, small)


def test_the_chain_on_its_own_silhouette_scores_the_inside_cap():
    q = np.array([0.9, -0.7, -0.6, 0.5])
    scene = make_scene(q, inside_cap_px=3.0)
    task = ImageTask(scene.body, [View(scene.camera, scene.support)])
    value = task.compute_value(Configuration(scene.body.model, q))
    assert 1.5 < value <= 3.0
    assert render_chain(scene.body, scene.camera, q).sum() > 0


class RenamedCamera:
    """A camera by composition, not a subclass of vision.camera.Camera: the View asks only for
    the CameraLike protocol (name, size, project, project_with_jacobian, pixel_radius)."""

    def __init__(self, camera, name):
        self._camera, self.name, self.size = camera, name, camera.size

    def project(self, points_world):
        return self._camera.project(points_world)

    def project_with_jacobian(self, points_world):
        return self._camera.project_with_jacobian(points_world)

    def pixel_radius(self, points_world, radii):
        return self._camera.pixel_radius(points_world, radii)


def test_any_camera_of_the_protocol_serves_a_view():
    q = np.array([0.4, 0.3, -0.9, 0.7])
    scene = make_scene(np.array([0.9, -0.7, -0.6, 0.5]))
    configuration = Configuration(scene.body.model, q)
    task = ImageTask(scene.body, [View(RenamedCamera(scene.camera, "wrapped"), scene.support)])
    reference = ImageTask(scene.body, [View(scene.camera, scene.support)])
    # A pinhole camera's samples are placed in the compiled reading, any other's by a product
    # (BLAS): the same values within rounding.
    assert task.compute_value(configuration) == pytest.approx(reference.compute_value(configuration), rel=1e-12)
    np.testing.assert_allclose(task.compute_gradient(configuration), reference.compute_gradient(configuration),
                               rtol=1e-12, atol=1e-12)
    small = SupportImage(np.zeros((240, 320), dtype=np.float32))
    with pytest.raises(InputError, match="camera 'wrapped': the support image"):
        View(RenamedCamera(scene.camera, "wrapped"), small)


def test_views_of_other_cameras_are_projected_by_those_cameras_not_the_kept_ones(human, rng):
    # The projections are kept while the same camera objects come (SegmentCriterion._projections):
    # views of other cameras, even of the same names and supports, must be read through the new ones.
    q = random_human_configuration(human, rng, spread=0.3)
    views = human_views(human, q)
    moved = []
    for view in views:
        center = view.camera.center_world
        moved.append(View(look_at_camera(view.camera.name, (320, 240), 300.0, center + [0.0, 0.3, 0.2],
                                         center + 3.0 * view.camera.rotation[2], np.array([0.0, 1.0, 0.0])),
                          view.support))
    task = ImageTask(human, views)
    before = task.compute_value(Configuration(human.model, q))
    task.set_views(moved)
    fresh = ImageTask(human, moved)
    after = task.compute_value(Configuration(human.model, q))
    assert after == fresh.compute_value(Configuration(human.model, q))
    assert after != before  # the moved cameras see the skeleton elsewhere on the same supports
    assert np.array_equal(task.compute_gradient(Configuration(human.model, q)),
                          fresh.compute_gradient(Configuration(human.model, q)))
