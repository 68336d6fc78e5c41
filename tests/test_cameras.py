"""Tests of ibik_pin.cameras: projection, its Jacobian, look-at cameras and calibration I/O."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from ibik_pin.exceptions import FileFormatError, InputError, UnknownNameError
from ibik_pin.io.calibration import read_calibration, write_calibration
from ibik_pin.vision.camera import OrthographicCamera, select_cameras
from ibik_pin.vision.pinhole import PinholeCamera, look_at_camera
from tests.paths import SHARED_DATA

DEMO_CALIBRATION = SHARED_DATA / "pose2sim_demo" / "Calib_qualisys_converted.toml"

CAMERA_SECTION = """\
[cam_01]
name = "cam_01"
size = [ 640.0, 480.0]
matrix = [ [ 500.0, 0.0, 320.0], [ 0.0, 510.0, 240.0], [ 0.0, 0.0, 1.0]]
distortions = [ -0.1, 0.01, 0.001, -0.002]
rotation = [ 0.1, -0.2, 0.3]
translation = [ 0.1, 0.2, 3.0]
fisheye = false
"""


def distorted_camera() -> PinholeCamera:
    """A camera with all five distortion terms non-zero and noticeable over the image."""
    intrinsics = np.array([[800.0, 0.0, 330.0], [0.0, 790.0, 250.0], [0.0, 0.0, 1.0]])
    distortion = np.array([-0.25, 0.08, 1.5e-3, -2.0e-3, 0.02])
    return PinholeCamera.from_rodrigues(
        "distorted", (640, 480), intrinsics, distortion, np.array([0.3, -0.4, 0.2]), np.array([0.1, -0.2, 3.0])
    )


def points_in_front(camera: PinholeCamera, count: int, seed: int) -> np.ndarray:
    """World points at 2-4 m in front of the camera, spread over a wide field of view."""
    rng = np.random.default_rng(seed)
    depth = rng.uniform(2.0, 4.0, count)
    normalized = rng.uniform(-0.5, 0.5, (count, 2))
    points_camera = np.column_stack((normalized * depth[:, None], depth))
    return (points_camera - camera.translation) @ camera.rotation


def tiny_camera(name: str) -> PinholeCamera:
    return look_at_camera(name, (10, 10), 10.0, [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])


def write_text(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_pinhole_projection_matches_cv2_project_points_to_1e9_px():
    camera = distorted_camera()
    points = points_in_front(camera, 200, seed=0)
    expected, _ = cv2.projectPoints(points, camera.rvec, camera.translation, camera.intrinsics, camera.distortion)
    np.testing.assert_allclose(camera.project(points), expected[:, 0], rtol=0.0, atol=1e-9)
    pixels, _, _ = camera.project_with_jacobian(points)
    np.testing.assert_allclose(pixels, expected[:, 0], rtol=0.0, atol=1e-9)


def test_pinhole_projection_with_four_distortion_terms_matches_cv2():
    camera = read_calibration(DEMO_CALIBRATION)[0] if DEMO_CALIBRATION.exists() else None
    if camera is None:
        pytest.skip("demo calibration not available")
    rng = np.random.default_rng(1)
    points = rng.normal([0.0, 1.0, 0.0], 0.4, (50, 3))
    expected, _ = cv2.projectPoints(points, camera.rvec, camera.translation, camera.intrinsics, camera.distortion)
    np.testing.assert_allclose(camera.project(points), expected[:, 0], rtol=0.0, atol=1e-9)


def test_pinhole_jacobian_matches_central_finite_differences_with_full_distortion():
    camera = distorted_camera()
    points = points_in_front(camera, 100, seed=2)
    _, jacobian, depth = camera.project_with_jacobian(points)
    assert jacobian.shape == (100, 2, 3)
    step = 1e-6  # [m]
    finite_difference = np.empty_like(jacobian)
    for axis in range(3):
        offset = np.zeros(3)
        offset[axis] = step
        finite_difference[:, :, axis] = (camera.project(points + offset) - camera.project(points - offset)) / (2 * step)
    relative_error = np.linalg.norm(jacobian - finite_difference, axis=(1, 2)) / np.linalg.norm(jacobian, axis=(1, 2))
    assert relative_error.max() <= 1e-6
    np.testing.assert_allclose(depth, camera.points_camera(points)[:, 2], rtol=0.0, atol=1e-12)


def test_a_projector_gives_each_cameras_projection_to_the_bit():
    """Pinhole cameras projected in one compiled call, a mixed list camera by camera; the pixels
    and depth alone (pixel_projector) the same."""
    from ibik_pin.vision.pinhole import pixel_projector, projector

    rng = np.random.default_rng(3)
    pinholes = [look_at_camera(f"c{k}", (640, 480), 600.0 + 50 * k, rng.normal(0.0, 1.0, 3) + [0.0, 0.0, 5.0],
                               np.zeros(3), np.array([0.0, 1.0, 0.0])) for k in range(3)] + [distorted_camera()]
    orthographic = OrthographicCamera("o", (640, 480), np.eye(3), np.zeros(3), 100.0, np.array([320.0, 240.0]))
    points = rng.normal(0.0, 0.5, (25, 3))
    for cameras in (pinholes, [pinholes[0], orthographic], []):
        projections = projector(cameras)(points)
        assert len(projections) == len(cameras)
        for camera, projection, (pixels, depth) in zip(cameras, projections, pixel_projector(cameras)(points),
                                                       strict=True):
            reference = camera.project_with_jacobian(points)
            for mine, expected in zip(projection, reference, strict=True):
                np.testing.assert_array_equal(mine, expected)
            np.testing.assert_array_equal(pixels, reference.pixels)
            np.testing.assert_array_equal(depth, reference.depth)


def test_pinhole_depth_is_the_z_coordinate_in_the_camera_frame():
    camera = look_at_camera("c", (320, 240), 300.0, eye=[0.0, 0.0, 5.0], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0])
    _, _, depth = camera.project_with_jacobian(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 7.0]]))
    np.testing.assert_allclose(depth, [5.0, -2.0], atol=1e-12)


def test_orthographic_projection_scales_camera_coordinates_and_has_a_constant_jacobian():
    rotation, _ = cv2.Rodrigues(np.array([0.2, 0.1, -0.3]))
    camera = OrthographicCamera("ortho", (200, 100), rotation, [0.1, 0.0, 2.0], 150.0, [99.5, 49.5])
    points = np.random.default_rng(3).normal(size=(20, 3))
    pixels, jacobian, depth = camera.project_with_jacobian(points)
    points_camera = points @ rotation.T + [0.1, 0.0, 2.0]
    np.testing.assert_allclose(pixels, 150.0 * points_camera[:, :2] + [99.5, 49.5], atol=1e-12)
    np.testing.assert_allclose(jacobian, np.broadcast_to(150.0 * rotation[:2], (20, 2, 3)), atol=1e-12)
    np.testing.assert_allclose(depth, points_camera[:, 2], atol=1e-12)
    np.testing.assert_allclose(camera.project(points), pixels, atol=1e-12)
    np.testing.assert_allclose(camera.pixel_radius(points, 0.1), np.full(20, 15.0), atol=1e-12)


def test_rodrigues_vector_and_camera_centre_round_trip():
    camera = distorted_camera()
    np.testing.assert_allclose(camera.rvec, [0.3, -0.4, 0.2], atol=1e-12)
    np.testing.assert_allclose(camera.points_camera(camera.center_world[None]), np.zeros((1, 3)), atol=1e-12)


def test_look_at_camera_sees_the_target_at_the_image_centre_with_up_pointing_up():
    camera = look_at_camera("c", (641, 481), 500.0, eye=[2.0, 1.0, 3.0], target=[0.0, 1.0, 0.0], up=[0.0, 1.0, 0.0])
    pixels = camera.project(np.array([[0.0, 1.0, 0.0], [0.0, 1.2, 0.0]]))
    np.testing.assert_allclose(pixels[0], [320.0, 240.0], atol=1e-9)
    assert pixels[1, 1] < pixels[0, 1] - 10.0
    np.testing.assert_allclose(camera.center_world, [2.0, 1.0, 3.0], atol=1e-12)


def test_pinhole_pixel_radius_is_focal_times_radius_over_depth_and_nan_behind():
    camera = look_at_camera("c", (320, 240), 400.0, eye=[0.0, 0.0, 4.0], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0])
    radius = camera.pixel_radius(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 6.0]]), np.array([0.1, 0.1]))
    np.testing.assert_allclose(radius[0], 400.0 * 0.1 / 4.0, atol=1e-12)
    assert np.isnan(radius[1])


def test_camera_rejects_a_matrix_that_is_not_a_rotation():
    with pytest.raises(InputError, match=r"rotation: expected a rotation matrix.*determinant"):
        PinholeCamera("c", (10, 10), np.eye(3), np.zeros(4), np.diag([1.0, 1.0, -1.0]), np.zeros(3))


def test_projection_rejects_points_of_the_wrong_shape():
    with pytest.raises(InputError, match=r"points_world: expected an array of shape \(N, 3\).*found shape \(4, 2\)"):
        distorted_camera().project(np.zeros((4, 2)))


def test_read_calibration_reads_the_pose2sim_demo_and_ignores_metadata():
    if not DEMO_CALIBRATION.exists():
        pytest.skip("demo calibration not available")
    cameras = read_calibration(DEMO_CALIBRATION)
    assert [camera.name for camera in cameras] == ["cam_01", "cam_02", "cam_03", "cam_04"]
    assert cameras[0].size == (1088, 1920)
    assert cameras[0].distortion.shape == (4,)
    np.testing.assert_allclose(cameras[0].rvec, [1.68827548, 1.04832205, -0.41955852], atol=1e-8)


def test_write_then_read_calibration_gives_the_same_projections(tmp_path):
    cameras = [
        distorted_camera(),
        look_at_camera("side view", (320, 240), 300.0, [3.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]),
    ]
    path = tmp_path / "calibration.toml"
    write_calibration(path, cameras)
    cameras_read = read_calibration(path)
    assert [camera.name for camera in cameras_read] == ["distorted", "side view"]
    points = points_in_front(cameras[0], 30, seed=4)
    for written, read in zip(cameras, cameras_read, strict=True):
        assert read.size == written.size
        np.testing.assert_allclose(read.project(points), written.project(points), rtol=0.0, atol=1e-9)
    assert [p.name for p in tmp_path.iterdir()] == ["calibration.toml"]


def test_write_calibration_rejects_an_orthographic_camera(tmp_path):
    camera = OrthographicCamera("ortho", (10, 10), np.eye(3), np.zeros(3), 1.0, [0.0, 0.0])
    with pytest.raises(InputError, match=r"cameras\[0\]: expected a PinholeCamera.*found OrthographicCamera"):
        write_calibration(tmp_path / "c.toml", [camera])


def test_read_calibration_names_file_section_and_missing_key(tmp_path):
    path = write_text(tmp_path / "c.toml", CAMERA_SECTION.replace("distortions = [ -0.1, 0.01, 0.001, -0.002]\n", ""))
    with pytest.raises(FileFormatError, match=r"c\.toml', section \[cam_01\]: missing key 'distortions'"):
        read_calibration(path)


def test_read_calibration_names_the_key_with_the_wrong_shape(tmp_path):
    text = CAMERA_SECTION.replace("rotation = [ 0.1, -0.2, 0.3]", "rotation = [ 0.1, -0.2]")
    path = write_text(tmp_path / "c.toml", text)
    expected = r"section \[cam_01\], key 'rotation'.*expected shape \(3,\), found shape \(2,\)"
    with pytest.raises(FileFormatError, match=expected):
        read_calibration(path)


def test_read_calibration_rejects_a_non_finite_value(tmp_path):
    text = CAMERA_SECTION.replace("translation = [ 0.1, 0.2, 3.0]", "translation = [ 0.1, nan, 3.0]")
    path = write_text(tmp_path / "c.toml", text)
    with pytest.raises(FileFormatError, match=r"key 'translation'.*expected finite values"):
        read_calibration(path)


def test_read_calibration_says_fisheye_is_not_supported(tmp_path):
    path = write_text(tmp_path / "c.toml", CAMERA_SECTION.replace("fisheye = false", "fisheye = true"))
    with pytest.raises(FileFormatError, match=r"section \[cam_01\], key 'fisheye': fisheye = true is not supported"):
        read_calibration(path)


def test_read_calibration_reports_unparsable_toml_and_missing_files(tmp_path):
    path = write_text(tmp_path / "broken.toml", "[cam_01\nname = ")
    with pytest.raises(FileFormatError, match=r"broken\.toml': expected valid TOML"):
        read_calibration(path)
    with pytest.raises(FileFormatError, match=r"absent\.toml: cannot read this calibration file"):
        read_calibration(tmp_path / "absent.toml")


def test_read_calibration_needs_at_least_one_camera(tmp_path):
    path = write_text(tmp_path / "c.toml", "[metadata]\nadjusted = false\n")
    with pytest.raises(FileFormatError, match=r"expected at least one camera section, found sections \['metadata'\]"):
        read_calibration(path)


def test_select_cameras_returns_the_requested_cameras_in_the_given_order():
    cameras = [tiny_camera(name) for name in "abc"]
    assert [camera.name for camera in select_cameras(cameras, ["c", "a"])] == ["c", "a"]


def test_select_cameras_lists_the_available_names_for_an_unknown_one():
    cameras = [tiny_camera(name) for name in "ab"]
    expected = r"^names: unknown camera name\(s\) \['z'\]; the calibration has \['a', 'b'\]"
    with pytest.raises(UnknownNameError, match=expected) as raised:
        select_cameras(cameras, ["a", "z"])
    assert raised.value.parameter == "names"
