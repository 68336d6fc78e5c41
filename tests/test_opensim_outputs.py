"""`ibik track` outputs opened where users open them: OpenSim (model.osim + motion.mot, joints.trc)
and a Pose2Sim-style TRC reader, on the TRC that Pose2Sim wrote for its demo (HALPE_26, Y up, no Hip).

The OpenSim checks run with OpenSim's own Python package (`opensim`, in the test extra); the XML
checks run everywhere and hold the model to OpenSim 4.x's documented layout.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest

from ibik_pin.cli import main
from ibik_pin.io.mot import read_mot
from ibik_pin.io.osim import OSIM_VERSION, osim_bodies
from ibik_pin.io.trc import read_trc
from tests.paths import TEST_DATA

POSE2SIM_TRC = TEST_DATA / "pose2sim_balancing_excerpt.trc"
# Markers of the played model against joints.trc [m]: within 1 mm.
MARKER_TOLERANCE_M = 1e-3
# joints.trc is written with 6+ significant digits; the Hip midpoint is computed from the same model.
HIP_TOLERANCE_M = 1e-6


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """Scaled from the targets' own distances (no static trial)."""
    out = tmp_path_factory.mktemp("pose2sim") / "out"
    assert main(["track", "--targets", str(POSE2SIM_TRC), "--no-image", "--quiet", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def calibrated_outputs(tmp_path_factory):
    """A subject calibrated on the same frames as its static trial (keypoints placed off the joints)."""
    out = tmp_path_factory.mktemp("pose2sim_calibrated") / "out"
    assert main(["track", "--targets", str(POSE2SIM_TRC), "--static", str(POSE2SIM_TRC), "--no-image", "--quiet",
                 "--out", str(out)]) == 0
    return out


def pose2sim_style_trc(path):
    """A TRC read the way Pose2Sim reads one: names on line 4, X/Y/Z on line 5, then rows of
    Frame#, Time and 3 values per marker (a blank line before the rows is skipped)."""
    lines = path.read_text().splitlines()
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t"), strict=True))
    names = [name for name in lines[3].split("\t")[2:] if name]
    rows = np.array([[float(cell) for cell in line.split("\t")] for line in lines[5:] if line.strip()])
    return header, names, rows


def test_joints_trc_reads_as_pose2sim_reads_it_with_halpe26_hip_at_the_hip_midpoint(outputs):
    header, names, rows = pose2sim_style_trc(outputs / "joints.trc")

    assert int(header["NumMarkers"]) == len(names) and int(header["NumFrames"]) == len(rows) == 30
    assert header["Units"] == "m" and float(header["DataRate"]) == 60.0
    assert rows.shape[1] == 2 + 3 * len(names)
    np.testing.assert_array_equal(rows[:, 0], np.arange(1, 31))
    positions = rows[:, 2:].reshape(len(rows), len(names), 3)
    hip, left, right = (positions[:, names.index(name)] for name in ("Hip", "LHip", "RHip"))
    np.testing.assert_allclose(hip, 0.5 * (left + right), atol=HIP_TOLERANCE_M)


def test_model_osim_follows_opensim_4_layout_with_the_mot_coordinates_and_every_keypoint(outputs):
    model = ElementTree.parse(outputs / "model.osim").getroot()
    mot = read_mot(outputs / "motion.mot")
    joints_trc = read_trc(outputs / "joints.trc")

    assert model.tag == "OpenSimDocument" and model.get("Version") == OSIM_VERSION
    bodies = {body.get("name") for body in model.iter("Body")}
    coordinates = [coordinate.get("name") for coordinate in model.iter("Coordinate")]
    assert sorted(coordinates) == sorted(mot.column_names)
    for joint in model.iter("CustomJoint"):
        frames = {frame.get("name"): frame.findtext("socket_parent") for frame in joint.iter("PhysicalOffsetFrame")}
        assert set(frames) == {joint.findtext("socket_parent_frame"), joint.findtext("socket_child_frame")}
        assert all(socket == "/ground" or socket.removeprefix("/bodyset/") in bodies for socket in frames.values())
        axes = joint.find("SpatialTransform").findall("TransformAxis")
        assert [axis.get("name") for axis in axes] == [f"rotation{i}" for i in (1, 2, 3)] + \
            [f"translation{i}" for i in (1, 2, 3)]
        rotations = np.array([[float(v) for v in axis.findtext("axis").split()] for axis in axes[:3]])
        assert np.linalg.matrix_rank(rotations) == 3  # OpenSim refuses dependent rotation axes
    markers = {marker.get("name"): marker.findtext("socket_parent_frame") for marker in model.iter("Marker")}
    assert set(markers) == set(joints_trc.marker_names)
    assert all(socket.removeprefix("/bodyset/") in bodies for socket in markers.values())


def test_the_human_merges_each_ball_joint_into_one_opensim_body(human):
    bodies = {body.name: [human.model.names[j] for j in body.joint_ids] for body in osim_bodies(human)}

    assert len(bodies) == 18
    assert bodies["pelvis"] == ["root_joint"]
    assert bodies["left_hip"] == ["left_hip_Z", "left_hip_X", "left_hip_Y"]
    assert bodies["right_knee"] == ["right_knee_Z"]


@pytest.mark.parametrize("run", ["outputs", "calibrated_outputs"])
def test_opensim_plays_model_osim_with_motion_mot_onto_joints_trc(run, request):
    opensim = pytest.importorskip("opensim", reason="OpenSim's Python package (pip install 'ibik_pin[opensim]')")
    outputs = request.getfixturevalue(run)
    model = opensim.Model(str(outputs / "model.osim"))
    state = model.initSystem()
    motion = opensim.TimeSeriesTable(str(outputs / "motion.mot"))
    markers = opensim.TimeSeriesTableVec3(str(outputs / "joints.trc"))
    labels = list(motion.getColumnLabels())
    marker_names = list(markers.getColumnLabels())
    coordinates = model.getCoordinateSet()
    worst = 0.0
    assert motion.getNumRows() == markers.getNumRows() == 30
    for row in range(motion.getNumRows()):
        values = motion.getRowAtIndex(row)
        for column, label in enumerate(labels):
            coordinate = coordinates.get(label)
            rotational = coordinate.getMotionType() == opensim.Coordinate.Rotational
            coordinate.setValue(state, np.deg2rad(values[column]) if rotational else values[column], False)
        model.realizePosition(state)
        expected = markers.getRowAtIndex(row)
        for column, name in enumerate(marker_names):
            played = model.getMarkerSet().get(name).getLocationInGround(state)
            written = expected[column]
            worst = max(worst, float(np.linalg.norm([played[i] - written[i] for i in range(3)])))
    print(f"worst marker distance: {worst * 1000:.6f} mm")
    assert worst < MARKER_TOLERANCE_M, f"worst marker {worst * 1000:.4f} mm off joints.trc"
