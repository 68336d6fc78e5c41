"""Calibrations of other systems read by content: Qualisys .qca.txt (Pose2Sim's demo, against
Pose2Sim's own conversion), EasyMocap's intri.yml + extri.yml, Anipose's TOML; unknown ones named."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ibik_pin.exceptions import FileFormatError
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import read_trc
from tests.paths import TEST_DATA

QUALISYS = TEST_DATA / "pose2sim_calibration" / "Calib.qca.txt"
CONVERTED = TEST_DATA / "pose2sim_calibration" / "Calib_qualisys_converted.toml"


def _reference_points_world() -> np.ndarray:
    """Pose2Sim's triangulation of the demo (Y-up TRC) in the calibration's world [m]."""
    trc = read_trc(TEST_DATA / "pose2sim_balancing_excerpt.trc")
    points = trc.positions.reshape(-1, 3)
    return points[np.isfinite(points).all(axis=1)] @ POSE2SIM_TRC_TO_WORLD.T


def test_a_qualisys_calibration_gives_the_cameras_of_pose2sims_conversion():
    qualisys, converted = read_calibration(QUALISYS), read_calibration(CONVERTED)
    assert [camera.name for camera in qualisys] == ["cam01", "cam02", "cam03", "cam04"]
    points = _reference_points_world()
    for ours, theirs in zip(qualisys, converted, strict=True):
        assert ours.size == theirs.size == (1088, 1920)
        np.testing.assert_allclose(ours.intrinsics, theirs.intrinsics, rtol=1e-12)
        np.testing.assert_allclose(ours.distortion, theirs.distortion, rtol=1e-12)
        np.testing.assert_allclose(ours.rotation, theirs.rotation, atol=1e-12)
        np.testing.assert_allclose(ours.translation, theirs.translation, atol=1e-12)
        # The subject projects to the same pixels: the same joints follow from either file.
        np.testing.assert_allclose(ours.project(points), theirs.project(points), atol=1e-6)


def test_a_qualisys_camera_with_a_missing_attribute_is_named(tmp_path):
    broken = QUALISYS.read_text().replace('focalLengthU="107599.671875"', "", 1)
    (tmp_path / "broken.qca.txt").write_text(broken)
    with pytest.raises(FileFormatError, match=r"camera 'cam01': attribute focalLengthU: expected a finite number"):
        read_calibration(tmp_path / "broken.qca.txt")


def _write_easymocap(folder, cameras, with_size: bool) -> None:
    """intri.yml and extri.yml as EasyMocap writes them (OpenCV FileStorage)."""
    intri = cv2.FileStorage(str(folder / "intri.yml"), cv2.FILE_STORAGE_WRITE)
    extri = cv2.FileStorage(str(folder / "extri.yml"), cv2.FILE_STORAGE_WRITE)
    for storage in (intri, extri):
        storage.startWriteStruct("names", cv2.FileNode_SEQ)
        for camera in cameras:
            storage.write("", camera.name)
        storage.endWriteStruct()
    for camera in cameras:
        intri.write(f"K_{camera.name}", np.asarray(camera.intrinsics))
        intri.write(f"dist_{camera.name}", np.asarray(camera.distortion)[None])
        if with_size:
            intri.write(f"H_{camera.name}", camera.size[1])
            intri.write(f"W_{camera.name}", camera.size[0])
        extri.write(f"R_{camera.name}", cv2.Rodrigues(np.asarray(camera.rotation))[0])
        extri.write(f"Rot_{camera.name}", np.asarray(camera.rotation))
        extri.write(f"T_{camera.name}", np.asarray(camera.translation)[:, None])
    intri.release()
    extri.release()


def test_an_easymocap_calibration_reads_from_either_file_or_its_folder(tmp_path):
    cameras = read_calibration(CONVERTED)
    _write_easymocap(tmp_path, cameras, with_size=True)
    points = _reference_points_world()
    for path in (tmp_path / "intri.yml", tmp_path / "extri.yml", tmp_path):
        read = read_calibration(path)
        assert [camera.name for camera in read] == [camera.name for camera in cameras]
        for ours, theirs in zip(read, cameras, strict=True):
            assert ours.size == theirs.size
            np.testing.assert_allclose(ours.project(points), theirs.project(points), atol=1e-6)


def test_an_easymocap_calibration_without_sizes_takes_twice_the_principal_point_and_says_so(tmp_path):
    _write_easymocap(tmp_path, read_calibration(CONVERTED)[:1], with_size=False)
    with pytest.warns(UserWarning, match=r"no H_cam_01, W_cam_01; its image size is taken as twice its principal"):
        (camera,) = read_calibration(tmp_path / "intri.yml")
    assert camera.size == (1066, 1896)


def test_an_easymocap_file_without_its_partner_is_refused_naming_it(tmp_path):
    _write_easymocap(tmp_path, read_calibration(CONVERTED)[:1], with_size=True)
    (tmp_path / "extri.yml").unlink()
    with pytest.raises(FileFormatError, match=r"intri\.yml and extri\.yml side by side; extri\.yml is missing"):
        read_calibration(tmp_path / "intri.yml")


def test_an_anipose_calibration_with_five_distortions_and_no_fisheye_key_reads(tmp_path):
    (tmp_path / "calibration.toml").write_text(
        '[cam_0]\nname = "A"\nsize = [640, 480]\nmatrix = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]\n'
        "distortions = [-0.1, 0.01, 0.0, 0.0, 0.001]\nrotation = [0.1, 0.2, 0.3]\ntranslation = [0.0, 0.5, 4.0]\n\n"
        '[metadata]\nadjusted = false\nerror = 0.3\n')
    (camera,) = read_calibration(tmp_path / "calibration.toml")
    assert camera.name == "A" and camera.distortion.shape == (5,)


def test_an_unknown_format_is_refused_naming_the_supported_ones(tmp_path):
    (tmp_path / "calib.txt").write_text("camera 1: f=800 cx=320\n")
    with pytest.raises(FileFormatError, match=r"expected valid TOML \(or one of the other formats read: Qualisys "
                                              r"\.qca\.txt, EasyMocap intri\.yml \+ extri\.yml\)"):
        read_calibration(tmp_path / "calib.txt")


def test_convert_calibration_writes_the_qualisys_cameras_as_pose2sim_toml(tmp_path, capsys):
    from ibik_pin.cli import main

    out = tmp_path / "calib.toml"
    assert main(["convert-calibration", str(QUALISYS), "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    points = _reference_points_world()
    for converted, original in zip(read_calibration(out), read_calibration(QUALISYS), strict=True):
        assert converted.name == original.name and converted.size == original.size
        np.testing.assert_allclose(converted.project(points), original.project(points), atol=1e-9)
    # An existing file is the user's: refused, left as it was.
    before = out.read_bytes()
    assert main(["convert-calibration", str(QUALISYS), "--out", str(out)]) == 2
    assert "the file exists" in capsys.readouterr().err and out.read_bytes() == before
