"""C3D in: real CMU Vicon data (an excerpt of 39_01.c3d), marker sets mapped to keypoints, gaps."""

from pathlib import Path

import numpy as np
import pytest

from ibik_pin.exceptions import FileFormatError, UnknownNameError
from ibik_pin.io.c3d import markers_to_keypoints, read_c3d, read_c3d_markers, read_mapping
from ibik_pin.io.trc import TrcData, read_trc
from tests.c3d_files import write_c3d

ezc3d = pytest.importorskip("ezc3d")
DATA = Path(__file__).parent / "data"
CMU_C3D = DATA / "cmu_39_01_first60.c3d"


def _without(markers: TrcData, drop) -> TrcData:
    keep = [index for index, name in enumerate(markers.marker_names) if not drop(name)]
    return TrcData([markers.marker_names[i] for i in keep], markers.times, markers.positions[:, keep],
                   markers.units, markers.data_rate, markers.frame_numbers)


def test_cmu_vicon_joint_points_become_the_keypoints_in_the_files_units_and_rate():
    keypoints = read_c3d(CMU_C3D)
    assert keypoints.units == "mm" and keypoints.data_rate == 120.0
    assert keypoints.positions.shape == (60, 19, 3) and not np.isnan(keypoints.positions).any()
    assert {"Hip", "Neck", "Head", "LKnee", "RElbow", "LWrist", "RBigToe", "LHeel"} <= set(keypoints.marker_names)
    position = dict(zip(keypoints.marker_names, np.transpose(keypoints.positions, (1, 0, 2)), strict=True))
    thigh = np.linalg.norm(position["LHip"] - position["LKnee"], axis=1)
    # BodyBuilder's points are a rigid skeleton: a segment's length is the same in every frame.
    assert 350 < thigh.mean() < 450 and thigh.std() < 0.5
    np.testing.assert_allclose(position["Hip"], (position["LHip"] + position["RHip"]) / 2)


def test_labels_lose_their_subject_prefix_and_positions_match_the_file():
    markers = read_c3d_markers(CMU_C3D)
    assert "LKNE" in markers.marker_names and not any(":" in name for name in markers.marker_names)
    raw = ezc3d.c3d(str(CMU_C3D))["data"]["points"]
    np.testing.assert_array_equal(markers.positions[5, markers.marker_names.index("LKNE")],
                                  raw[:3, markers.marker_names.index("LKNE"), 5])


def test_plug_in_gait_markers_alone_give_hip_centres_by_regression_within_5_cm_of_vicons():
    markers = read_c3d_markers(CMU_C3D)
    vicon = markers_to_keypoints(markers)
    markers_only = markers_to_keypoints(_without(markers, lambda name: name.endswith("0")))
    for name in ("LHip", "RHip", "Hip"):
        offset = np.linalg.norm(markers_only.positions[:, markers_only.marker_names.index(name)]
                                - vicon.positions[:, vicon.marker_names.index(name)], axis=1)
        # CMU's pelvis markers are waist markers a few cm above the ASIS the regression assumes.
        assert offset.mean() < 50.0, name


def test_a_c3d_of_keypoints_reads_back_as_its_trc_with_gaps_as_nan(tmp_path):
    trc = read_trc(DATA / "pose2sim_balancing_excerpt.trc")
    positions_mm = trc.positions * 1000.0
    positions_mm[7, 3] = np.nan
    write_c3d(tmp_path / "targets.c3d", trc.marker_names, positions_mm, trc.data_rate)
    read = read_c3d(tmp_path / "targets.c3d")
    assert read.marker_names == [name for name in read.marker_names if name in trc.marker_names]
    for index, name in enumerate(read.marker_names):
        expected = positions_mm[:, trc.marker_names.index(name)]
        np.testing.assert_allclose(read.positions[:, index], expected, atol=1e-3)  # 32-bit floats [mm]
    assert np.isnan(read.positions[7, read.marker_names.index(trc.marker_names[3])]).all()
    assert read.data_rate == trc.data_rate


def test_a_mapping_file_chooses_the_markers_and_an_unknown_one_is_named_with_the_closest(tmp_path):
    mapping = tmp_path / "mapping.toml"
    mapping.write_text('[keypoints]\nLKnee = ["LKNE"]\nLWrist = ["LWRA", "LWRB"]\n')
    keypoints = read_c3d(CMU_C3D, mapping)
    markers = read_c3d_markers(CMU_C3D)
    assert keypoints.marker_names == ["LKnee", "LWrist"]
    column = markers.marker_names.index
    np.testing.assert_allclose(keypoints.positions[:, 1],
                               (markers.positions[:, column("LWRA")] + markers.positions[:, column("LWRB")]) / 2)
    assert read_mapping(mapping) == {"LKnee": ("LKNE",), "LWrist": ("LWRA", "LWRB")}
    with pytest.raises(UnknownNameError, match=r"keypoint LKnee: marker 'LKNEE' is not in the file \(closest: LKNE"):
        read_c3d(CMU_C3D, {"LKnee": ["LKNEE"]})


def test_a_file_that_is_not_c3d_or_a_bad_mapping_is_one_file_format_error(tmp_path):
    (tmp_path / "x.c3d").write_text("not a c3d file")
    with pytest.raises(FileFormatError, match=r"x\.c3d': cannot read it as C3D"):
        read_c3d_markers(tmp_path / "x.c3d")
    with pytest.raises(FileFormatError, match="no such file"):
        read_c3d_markers(tmp_path / "absent.c3d")
    (tmp_path / "m.toml").write_text("[keypoints]\nLKnee = 3\n")
    with pytest.raises(FileFormatError, match=r"keypoints\.LKnee: expected a list of marker names, found 3"):
        read_mapping(tmp_path / "m.toml")


def test_cmus_raw_vicon_recording_is_tracked_from_its_c3d_z_up_as_the_file_declares(tmp_path):
    import json

    from ibik_pin.cli import main

    out = tmp_path / "out"
    assert main(["track", "--targets", str(CMU_C3D), "--no-image", "--quiet", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert (report["trc_axes"]["used"], report["trc_axes"]["how"]) == ("z-up", "declared by the C3D file")
    # Vicon's joint points are joint centres, as the model's keypoints: met to millimetres, scaled from
    # their own distances (heels and toes are skin markers, off the model's foot points).
    joint_centres = ("LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle", "LElbow", "RElbow", "LWrist", "RWrist")
    worst_mm = max(1000 * report["keypoint_residual_m"][name]["mean"] for name in joint_centres)
    assert worst_mm < 5.0
    assert read_trc(out / "joints.trc").positions.shape[0] == 60
