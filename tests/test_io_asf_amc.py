"""Tests of ibik_pin.io.asf and asf_amc: CMU skeletons and walks, conventions, malformed files."""

import re

import numpy as np
import pytest

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.asf_amc import read_asf_amc
from tests.paths import SHARED_DATA, TEST_DATA

SHARED_CMU = SHARED_DATA / "cmu"
needs_shared_cmu = pytest.mark.skipif(
    not SHARED_CMU.is_dir(), reason="the shared CMU data is not beside the repository"
)
METRES_PER_CMU_UNIT = (1.0 / 0.45) * 0.0254
FOOT_POINTS = ("lfoot", "rfoot", "ltoes", "rtoes")


@pytest.fixture(scope="module")
def excerpt():
    """The first 60 frames of CMU 35_01 (walking)."""
    return read_asf_amc(TEST_DATA / "35.asf", TEST_DATA / "35_01_excerpt.amc")


@pytest.fixture(scope="module")
def walk():
    """The whole of CMU 35_01, 358 frames at 120 Hz."""
    if not SHARED_CMU.is_dir():
        pytest.skip("the shared CMU data is not beside the repository")
    return read_asf_amc(SHARED_CMU / "35.asf", SHARED_CMU / "35_01.amc")


def test_the_joints_are_the_root_and_every_bone_end_depth_first(excerpt):
    assert excerpt.positions.shape == (60, 31, 3)
    assert excerpt.names[:6] == ["root", "lhipjoint", "lfemur", "ltibia", "lfoot", "ltoes"]
    assert excerpt.parents[excerpt.index("ltibia")] == excerpt.index("lfemur")
    assert excerpt.parents[excerpt.index("lhipjoint")] == 0
    assert excerpt.frame_rate == 120.0


def test_bone_lengths_are_the_asf_lengths_in_metres_at_every_frame(excerpt):
    lengths = excerpt.bone_lengths()

    # 35.asf: lfemur length 7.41015, rtibia 7.99175, head 1.74399, lthumb 0.521313, in 1/0.45 inch
    for name, asf_length in [
        ("lfemur", 7.41015),
        ("rtibia", 7.99175),
        ("head", 1.74399),
        ("lthumb", 0.521313),
    ]:
        np.testing.assert_allclose(
            lengths[:, excerpt.index(name)], asf_length * METRES_PER_CMU_UNIT, atol=1e-9
        )
    assert lengths.std(axis=0).max() < 1e-6


def test_the_walker_has_the_left_hip_on_the_left_and_the_toes_ahead(excerpt):
    positions = excerpt.positions
    forward = positions[-1, 0] - positions[0, 0]
    forward[1] = 0.0
    forward /= np.linalg.norm(forward)
    left = np.cross([0.0, 1.0, 0.0], forward)  # Y up

    hips = positions[:, excerpt.index("lhipjoint")] - positions[:, excerpt.index("rhipjoint")]
    toes = positions[:, excerpt.index("ltoes")] - positions[:, excerpt.index("ltibia")]
    assert np.all(hips @ left > 0.15)  # [m]
    assert np.all(toes @ forward > 0.05)  # [m]


@needs_shared_cmu
def test_a_whole_cmu_walk_has_constant_bones_a_human_height_and_moves_forward(walk):
    positions = walk.positions
    feet = [walk.index(name) for name in FOOT_POINTS]

    assert positions.shape == (358, 31, 3)
    assert walk.bone_lengths().std(axis=0).max() < 1e-6
    height = positions[0, walk.index("head"), 1] - positions[0, feet, 1].min()
    assert 1.5 < height < 2.0  # foot to head [m]
    assert np.linalg.norm(positions[-1, 0, [0, 2]] - positions[0, 0, [0, 2]]) > 1.0  # [m]
    lowest_foot = positions[:, feet, 1].min(axis=1)
    assert np.all((lowest_foot > -0.02) & (lowest_foot < 0.1))  # one foot on the floor, y = 0


def test_the_frame_rate_is_the_argument_and_must_be_positive():
    motion = read_asf_amc(TEST_DATA / "35.asf", TEST_DATA / "35_01_excerpt.amc", frame_rate=60.0)

    assert motion.frame_rate == 60.0
    with pytest.raises(
        InputError, match=re.escape("frame_rate: expected a positive number [Hz], got 0.0")
    ):
        read_asf_amc(TEST_DATA / "35.asf", TEST_DATA / "35_01_excerpt.amc", frame_rate=0.0)


TINY_ASF = """:version 1.10
:name tiny
:units
  length 0.0254  # a file unit is then 1 m
  angle deg
:root
  order TX TY TZ RX RY RZ
  axis XYZ
  position 0 0 0
  orientation 0 0 0
:bonedata
  begin
    id 1
    name arm
    direction 1, 0, 0
    length 2
    axis 0 0 0 XYZ
    dof rz
    limits (-180.0 180.0)
  end
  begin
    id 2
    name hand
    direction 1 0 0
    length 1
    axis 90 0 0 XYZ
    dof ry
  end
:hierarchy
  begin
    root arm
    arm hand
  end
"""
TINY_AMC = ":FULLY-SPECIFIED\n:DEGREES\n1\nroot 1 0 0 0 0 0\narm 90\nhand 90\n"


def test_dofs_rotate_about_the_axes_of_the_bone_frame(tmp_path):
    (tmp_path / "tiny.asf").write_text(TINY_ASF)
    (tmp_path / "tiny.amc").write_text(TINY_AMC)

    motion = read_asf_amc(tmp_path / "tiny.asf", tmp_path / "tiny.amc")

    # arm: rz 90 turns +X to +Y. hand: its frame is the world's turned 90 deg about X, so its
    # ry 90 turns about the world's Z, adding to the arm's: the hand points along -X.
    np.testing.assert_allclose(
        motion.positions[0], [[1.0, 0.0, 0.0], [1.0, 2.0, 0.0], [0.0, 2.0, 0.0]], atol=1e-12
    )


ASF = (TEST_DATA / "35.asf").read_text()
AMC = (TEST_DATA / "35_01_excerpt.amc").read_text()


@pytest.mark.parametrize(
    ("asf", "amc", "message"),
    [
        (
            ASF.replace(":hierarchy", ":hierarchies"),
            AMC,
            "expected a ':hierarchy' section, found none",
        ),
        (
            ASF.replace("angle deg", "angle grad"),
            AMC,
            "line 8: units angle: expected 'deg' or 'rad', got ['grad']",
        ),
        (
            ASF.replace("length 0.45", "length -1"),
            AMC,
            "line 7: units length: expected a positive number",
        ),
        (
            ASF.replace("length 7.41015", "length long"),
            AMC,
            "line 29: lfemur length: expected 1 number(s), got ['long']",
        ),
        (
            ASF.replace("axis 0 0 20  XYZ", "axis 0 0 20  XXY"),
            AMC,
            "line 30: lfemur axis: expected an order of X, Y and Z",
        ),
        (
            ASF.replace(
                "dof rx ry rz\n    limits (-160.0 20.0)", "dof rx ty rz\n    limits (-160.0 20.0)"
            ),
            AMC,
            "line 31: lfemur dof: expected distinct values among rx ry rz",
        ),
        (
            ASF.replace("lfemur ltibia", "lfemur ltibiae"),
            AMC,
            ":hierarchy: 'ltibiae' is not a bone of :bonedata",
        ),
        (
            ASF.replace("    lfemur ltibia\n", ""),
            AMC,
            "expected every bone below the root, but ['ltibia', 'lfoot', 'ltoes'] are not",
        ),
        (
            ASF,
            AMC.replace("lfemur", "lthigh", 1),
            "line 30: 'lthigh' is not a bone with dofs of the ASF",
        ),
        (
            ASF,
            AMC.replace("rtibia 25.6934\n", "", 1),
            "line 4: the frame starting here lacks ['rtibia']",
        ),
        (
            ASF,
            AMC.replace("rtibia 25.6934", "rtibia 25.6934 1.0", 1),
            "line 27: rtibia: expected 1 number(s), got ['25.6934', '1.0']",
        ),
        (ASF, AMC.replace("\n2\n", "\n3\n", 1), "line 34: expected frame 2, got 3"),
        (
            ASF,
            AMC.replace(":DEGREES", ":RADIANS"),
            "line 3: :RADIANS disagrees with the ASF's units angle (deg)",
        ),
        (ASF, ":FULLY-SPECIFIED\n:DEGREES\n", "expected at least one frame, found none"),
    ],
    ids=[
        "no hierarchy",
        "unknown angle unit",
        "negative length unit",
        "length not a number",
        "axis order with a repeated axis",
        "translation dof",
        "unknown bone in the hierarchy",
        "bones not below the root",
        "unknown bone in the AMC",
        "bone missing from a frame",
        "too many values",
        "frame numbers skip",
        "AMC angles in radians",
        "no frame",
    ],
)
def test_malformed_files_raise_file_format_errors_naming_the_problem(tmp_path, asf, amc, message):
    (tmp_path / "bad.asf").write_text(asf)
    (tmp_path / "bad.amc").write_text(amc)

    with pytest.raises(FileFormatError, match=re.escape(message)) as error:
        read_asf_amc(tmp_path / "bad.asf", tmp_path / "bad.amc")

    assert str(tmp_path) in str(error.value)
