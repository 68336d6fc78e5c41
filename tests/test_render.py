"""Tests of ibik_pin.render: capsule silhouettes and overlays."""

import numpy as np
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.vision.camera import OrthographicCamera
from ibik_pin.vision.pinhole import look_at_camera
from ibik_pin.vision.render import render_capsules
from ibik_pin.viz.drawing import draw_skeleton, overlay_mask

FOCAL_PX = 500.0
DEPTH_M = 3.0


def front_camera():
    """A 321 x 241 camera 3 m in front of the origin, looking along -z, y up."""
    return look_at_camera("front", (321, 241), FOCAL_PX, [0.0, 0.0, DEPTH_M], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])


def test_a_capsule_renders_along_its_projected_axis_with_the_expected_width():
    camera = front_camera()
    radius = 0.05  # [m]
    mask = render_capsules(camera, np.array([[-0.5, 0.0, 0.0]]), np.array([[0.5, 0.0, 0.0]]), np.array([radius]))
    assert mask.shape == (241, 321) and mask.dtype == bool
    centre_u, centre_v = np.rint(camera.project(np.zeros((1, 3)))[0]).astype(int)
    assert mask[centre_v, centre_u]
    assert not mask[10, 10] and not mask[centre_v + 40, centre_u]
    width_px = np.count_nonzero(mask[:, centre_u])
    assert width_px == pytest.approx(2.0 * FOCAL_PX * radius / DEPTH_M, abs=2.0)
    ends_u = np.flatnonzero(mask[centre_v])
    expected_half_length = FOCAL_PX * (0.5 + radius) / DEPTH_M
    assert ends_u[0] == pytest.approx(centre_u - expected_half_length, abs=2.0)
    assert ends_u[-1] == pytest.approx(centre_u + expected_half_length, abs=2.0)


def test_a_capsule_nearer_at_one_end_is_wider_there():
    camera = front_camera()
    mask = render_capsules(camera, np.array([[-0.6, 0.0, 1.5]]), np.array([[0.6, 0.0, -1.5]]), 0.05)
    columns = np.flatnonzero(mask.any(axis=0))
    left, right = columns[0] + 5, columns[-1] - 5
    assert np.count_nonzero(mask[:, left]) > np.count_nonzero(mask[:, right]) + 5


def test_spheres_render_as_discs_and_points_behind_the_camera_are_skipped():
    camera = front_camera()
    mask = render_capsules(
        camera,
        np.array([[0.0, 0.0, 4.0]]),
        np.array([[0.0, 0.1, 4.0]]),
        0.1,
        spheres_world=np.array([[0.3, 0.0, 0.0]]),
        sphere_radii=0.06,
    )
    centre = camera.project(np.array([[0.3, 0.0, 0.0]]))[0]
    rows, columns = np.nonzero(mask)
    assert np.hypot(columns - centre[0], rows - centre[1]).max() <= FOCAL_PX * 0.06 / DEPTH_M + 1.0
    assert np.count_nonzero(mask) == pytest.approx(np.pi * (FOCAL_PX * 0.06 / DEPTH_M) ** 2, rel=0.1)


def test_an_orthographic_camera_renders_capsules_with_scale_times_radius():
    camera = OrthographicCamera("ortho", (200, 100), np.eye(3), np.zeros(3), scale=100.0, principal_point=[99.5, 49.5])
    mask = render_capsules(camera, np.array([[-0.5, 0.0, 0.0]]), np.array([[0.5, 0.0, 0.0]]), 0.1)
    assert np.count_nonzero(mask[:, 100]) == pytest.approx(20.0, abs=2.0)
    assert np.count_nonzero(mask[50]) == pytest.approx(120.0, abs=2.0)


def test_render_capsules_rejects_ends_of_another_count():
    expected = r"ends_world: expected an array of shape \(2, 3\) \[m\], found shape \(1, 3\)"
    with pytest.raises(InputError, match=expected):
        render_capsules(front_camera(), np.zeros((2, 3)), np.zeros((1, 3)), 0.1)


def test_draw_skeleton_draws_on_a_copy():
    image = np.zeros((50, 60, 3), np.uint8)
    starts = np.array([[5.0, 25.0], [np.nan, 0.0]])
    ends = np.array([[55.0, 25.0], [1.0, 1.0]])
    drawn = draw_skeleton(image, starts, ends, (0, 255, 0), 3)
    assert image.max() == 0
    assert drawn[25, 30, 1] == 255 and drawn[25, 30, 0] == 0 and drawn[5, 30].max() == 0


def test_overlay_mask_blends_the_colour_only_inside_the_mask():
    image = np.full((20, 30, 3), 100, np.uint8)
    mask = np.zeros((20, 30), bool)
    mask[5:10, 5:10] = True
    blended = overlay_mask(image, mask, color=(0, 0, 255), alpha=0.5)
    np.testing.assert_array_equal(blended[7, 7], [50, 50, 178])
    np.testing.assert_array_equal(blended[0, 0], [100, 100, 100])
    expected = r"mask: expected a bool or uint8 array of shape \(20, 30\), found shape \(5, 5\)"
    with pytest.raises(InputError, match=expected):
        overlay_mask(image, np.zeros((5, 5), bool), (0, 0, 255), 0.5)
