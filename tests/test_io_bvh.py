"""Tests of ibik_pin.io.bvh, bvh_hierarchy and bvh_writer (and of the SkeletonMotion they
return): write, read, forward kinematics, real files, malformed files."""

import itertools
import re

import numpy as np
import pytest

from ibik_pin.exceptions import (
    FileFormatError,
    IbikWarning,
    InputError,
    UnknownNameError,
)
from ibik_pin.io.bvh import CMU_BVH_SCALE, read_bvh
from ibik_pin.io.bvh_writer import write_bvh
from tests.paths import SHARED_DATA, TEST_DATA

SHARED_BVH = SHARED_DATA / "bvh"
needs_shared_bvh = pytest.mark.skipif(
    not SHARED_BVH.is_dir(), reason="the shared BVH data is not beside the repository"
)
ROTATION_ORDERS = ["".join(order) for order in itertools.permutations("XYZ")]
POSITION_TOLERANCE = 1e-6  # [m]


def axis_rotation(axis: str, angle: float) -> np.ndarray:
    """The rotation matrix about one axis, written out (independent of ibik_pin)."""
    c, s = np.cos(angle), np.sin(angle)
    return {
        "X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def random_rotations(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Uniform random rotation matrices (normalised Gaussian quaternions), shape (*shape, 3, 3)."""
    w, x, y, z = np.moveaxis(rng.normal(size=(*shape, 4)), -1, 0)
    norm = np.sqrt(w**2 + x**2 + y**2 + z**2)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return np.stack(
        [
            np.stack([1 - 2 * (y**2 + z**2), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x**2 + z**2), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x**2 + y**2)], -1),
        ],
        -2,
    )


def random_skeleton(rng: np.random.Generator, joint_count: int = 12):
    """Names, parents (a random tree, not in depth-first order) and offsets [m]."""
    parents = np.array([-1] + [int(rng.integers(0, joint)) for joint in range(1, joint_count)])
    names = [f"joint{joint}" for joint in range(joint_count)]
    offsets = rng.normal(scale=0.2, size=(joint_count, 3))
    return names, parents, offsets


def reference_positions(names, parents, offsets, local_rotations, root_positions, end_sites):
    """World positions by name, (F, 3) [m], computed frame by frame and joint by joint."""
    positions = {name: [] for name in names}
    leaves = [joint for joint in range(len(names)) if joint not in parents]
    positions.update({f"{names[joint]}_end": [] for joint in leaves})
    parents_first, stack = [], [int(np.flatnonzero(parents == -1)[0])]
    while stack:
        joint = stack.pop()
        parents_first.append(joint)
        stack.extend(np.flatnonzero(parents == joint).tolist())
    for frame in range(local_rotations.shape[0]):
        world_rotations, world_positions = {}, {}
        for joint in parents_first:
            parent = parents[joint]
            if parent < 0:
                world_rotations[joint] = local_rotations[frame, joint]
                world_positions[joint] = root_positions[frame]
            else:
                world_rotations[joint] = world_rotations[parent] @ local_rotations[frame, joint]
                world_positions[joint] = (
                    world_positions[parent] + world_rotations[parent] @ offsets[joint]
                )
        for joint, name in enumerate(names):
            positions[name].append(world_positions[joint])
        for joint in leaves:
            end_offset = end_sites.get(joint, np.zeros(3))
            positions[f"{names[joint]}_end"].append(
                world_positions[joint] + world_rotations[joint] @ end_offset
            )
    return {name: np.array(values) for name, values in positions.items()}


@pytest.mark.parametrize("rotation_order", ROTATION_ORDERS)
def test_a_random_skeleton_written_and_read_back_has_the_same_joint_positions(
    tmp_path, rotation_order
):
    rng = np.random.default_rng(2024)
    names, parents, offsets = random_skeleton(rng)
    frame_count = 20
    local_rotations = random_rotations(rng, (frame_count, len(names)))
    root_positions = rng.normal(size=(frame_count, 3))
    leaves = [joint for joint in range(len(names)) if joint not in parents]
    end_sites = {leaves[0]: np.array([0.0, 0.1, 0.05])}

    write_bvh(
        tmp_path / "random.bvh",
        names,
        parents,
        offsets,
        local_rotations,
        root_positions,
        frame_time=0.01,
        rotation_order=rotation_order,
        end_sites=end_sites,
    )
    motion = read_bvh(tmp_path / "random.bvh", scale=1.0).to_skeleton_motion()

    expected = reference_positions(
        names, parents, offsets, local_rotations, root_positions, end_sites
    )
    assert sorted(motion.names) == sorted(expected)
    assert motion.frame_rate == pytest.approx(100.0, rel=1e-12)
    for name, positions in expected.items():
        np.testing.assert_allclose(
            motion.positions[:, motion.index(name)],
            positions,
            atol=POSITION_TOLERANCE,
            err_msg=name,
        )


@pytest.mark.parametrize("rotation_order", ROTATION_ORDERS)
def test_rotations_at_gimbal_lock_survive_the_euler_angles(tmp_path, rotation_order):
    rng = np.random.default_rng(5)
    names, parents, offsets = (
        ["root", "a", "b", "c"],
        np.array([-1, 0, 1, 2]),
        rng.normal(size=(4, 3)),
    )
    frame_count = 8
    first, last = rng.uniform(-np.pi, np.pi, size=(2, frame_count, 4))
    middle = np.where(rng.random((frame_count, 4)) < 0.5, np.pi / 2, -np.pi / 2)
    middle[:, 2] += 1e-9  # nearly, not exactly, locked
    i, j, k = rotation_order
    local_rotations = np.array(
        [
            [
                axis_rotation(i, first[f, n])
                @ axis_rotation(j, middle[f, n])
                @ axis_rotation(k, last[f, n])
                for n in range(4)
            ]
            for f in range(frame_count)
        ]
    )
    root_positions = np.zeros((frame_count, 3))
    end_sites = {3: np.array([0.3, -0.2, 0.1])}

    write_bvh(
        tmp_path / "locked.bvh",
        names,
        parents,
        offsets,
        local_rotations,
        root_positions,
        frame_time=0.02,
        rotation_order=rotation_order,
        end_sites=end_sites,
    )
    motion = read_bvh(tmp_path / "locked.bvh", scale=1.0).to_skeleton_motion()

    expected = reference_positions(
        names, parents, offsets, local_rotations, root_positions, end_sites
    )
    for name, positions in expected.items():
        np.testing.assert_allclose(
            motion.positions[:, motion.index(name)],
            positions,
            atol=POSITION_TOLERANCE,
            err_msg=name,
        )


def test_the_written_hierarchy_has_six_root_channels_and_three_per_joint(tmp_path):
    rng = np.random.default_rng(11)
    names, parents, offsets = (
        ["hips", "spine", "leg"],
        np.array([-1, 0, 0]),
        rng.normal(size=(3, 3)),
    )

    write_bvh(
        tmp_path / "small.bvh",
        names,
        parents,
        offsets,
        random_rotations(rng, (2, 3)),
        rng.normal(size=(2, 3)),
        frame_time=1 / 30,
        rotation_order="ZXY",
    )
    skeleton = read_bvh(tmp_path / "small.bvh").skeleton

    assert skeleton.names == ["hips", "spine", "spine_end", "leg", "leg_end"]
    np.testing.assert_array_equal(skeleton.parents, [-1, 0, 1, 0, 3])
    rotations = ["Zrotation", "Xrotation", "Yrotation"]
    assert skeleton.channels == [
        ["Xposition", "Yposition", "Zposition", *rotations],
        rotations,
        [],
        rotations,
        [],
    ]
    np.testing.assert_array_equal(skeleton.offsets[[2, 4]], np.zeros((2, 3)))


def test_the_boxing_excerpt_keeps_its_extra_frame_with_a_warning():
    with pytest.warns(
        IbikWarning, match="Frames is 60 but the file holds 61 frames; all frames are kept"
    ):
        bvh = read_bvh(TEST_DATA / "Boxing_Toes_excerpt.bvh", scale=0.01)
    motion = bvh.to_skeleton_motion()

    assert bvh.channel_values.shape == (61, 6 + 20 * 3)
    assert len(motion.names) == 21 + 5  # 21 joints and 5 end sites
    assert "LeftToes_end" in motion.names
    assert motion.frame_rate == pytest.approx(100.0, rel=1e-12)
    assert motion.bone_lengths().std(axis=0).max() < 1e-6
    heights = motion.positions[0, :, 1]
    assert 1.5 < heights.max() - heights.min() < 2.0  # a standing boxer, centimetres to metres


@needs_shared_bvh
def test_the_whole_boxing_file_holds_one_frame_more_than_it_declares():
    with pytest.warns(IbikWarning, match="Frames is 3069 but the file holds 3070 frames"):
        bvh = read_bvh(SHARED_BVH / "Boxing_Toes.bvh", scale=0.01)
    motion = bvh.to_skeleton_motion()

    assert motion.positions.shape == (3070, 26, 3)
    assert motion.bone_lengths().std(axis=0).max() < 1e-6


@needs_shared_bvh
@pytest.mark.parametrize("file_name", ["131_01.bvh", "131_03.bvh"])
def test_cmu_131_bone_lengths_are_constant_and_human_in_cmu_units(file_name):
    motion = read_bvh(SHARED_BVH / file_name, scale=CMU_BVH_SCALE).to_skeleton_motion()

    assert motion.frame_rate == pytest.approx(120.0, rel=1e-5)
    assert motion.bone_lengths().std(axis=0).max() < 1e-6
    lengths = motion.bone_lengths()[0]
    leg = lengths[motion.index("LeftKnee")] + lengths[motion.index("LeftAnkle")]
    assert 0.7 < leg < 1.0  # hip to ankle [m]: 1 file unit is 0.0254 / 0.45 m, not 1 m
    assert 0.8 < motion.positions[:, motion.index("Hips"), 1].mean() < 1.1


def test_motion_without_a_scale_refuses_to_guess_the_unit():
    with pytest.warns(IbikWarning):
        bvh = read_bvh(TEST_DATA / "Boxing_Toes_excerpt.bvh")

    with pytest.raises(InputError, match="scale: BVH files do not state their length unit"):
        bvh.to_skeleton_motion()
    assert bvh.to_skeleton_motion(scale=0.01).positions.shape == (61, 26, 3)


def test_skeleton_motion_finds_joints_slices_frames_and_names_unknown_joints():
    with pytest.warns(IbikWarning):
        motion = read_bvh(TEST_DATA / "Boxing_Toes_excerpt.bvh", scale=0.01).to_skeleton_motion()

    every_other = motion.subset(slice(10, 30, 2))

    assert motion.index("Hips") == 0
    assert every_other.positions.shape == (10, 26, 3)
    assert every_other.frame_rate == pytest.approx(50.0)
    np.testing.assert_array_equal(every_other.positions[1], motion.positions[12])
    np.testing.assert_array_equal(motion.bone_lengths()[:, 0], 0.0)
    with pytest.raises(
        UnknownNameError, match="joint 'Tail' does not exist; known joints: Hips, Ab, Chest"
    ):
        motion.index("Tail")


HIERARCHY = """HIERARCHY
ROOT hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT knee
  {
    OFFSET 0 -4 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -4 0
    }
  }
}
"""
MOTION = "MOTION\nFrames: 2\nFrame Time: 0.01\n" + "0 1 2 3 4 5 6 7 8\n" * 2


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (HIERARCHY, "expected a line 'MOTION' after the hierarchy, found none"),
        (
            HIERARCHY.replace("Xrotation Yrotation\n    End", "Wrotation Yrotation\n    End")
            + MOTION,
            "line 9: CHANNELS of 'knee': expected 3 distinct names among",
        ),
        (
            HIERARCHY.replace("OFFSET 0 -4 0\n    CHANNELS", "OFFSET 0 -4\n    CHANNELS") + MOTION,
            "line 9: OFFSET: expected 3 numbers, got ['0', '-4', 'CHANNELS']",
        ),
        (
            HIERARCHY.replace("End Site", "Ending Site") + MOTION,
            "line 10: in joint 'knee': expected JOINT, End Site or '}', got 'Ending'",
        ),
        (
            HIERARCHY.replace("JOINT knee", "JOINT hips") + MOTION,
            "line 6: joint name 'hips' appears twice",
        ),
        (
            HIERARCHY[: HIERARCHY.rindex("}")] + MOTION,
            "line 15: expected JOINT, End Site or '}', got 'MOTION' (the hierarchy is incomplete)",
        ),
        (
            HIERARCHY + MOTION.replace("0 1 2 3 4 5 6 7 8\n", "0 1 2 3 4 5 6 7\n", 1),
            "line 19: expected 9 channel values, got 8",
        ),
        (
            HIERARCHY + MOTION.replace("Frames: 2", "Frames: 3"),
            "Frames is 3 but the file holds 2 frames",
        ),
        (
            HIERARCHY + MOTION.replace("Frame Time: 0.01", "Frame Time: fast"),
            "line 18: Frame Time: expected a number, got 'fast'",
        ),
        (
            HIERARCHY + MOTION.replace("Frame Time: 0.01", "Frame Time: 0"),
            "line 18: Frame Time: expected a positive number [s], got 0.0",
        ),
        (
            HIERARCHY + MOTION.replace("Frames: 2", "Frame Count: 2"),
            "line 17: expected 'Frames: ...', got 'Frame Count: 2'",
        ),
        (
            HIERARCHY + MOTION.replace("0 1 2 3 4 5 6 7 8\n", "0 1 2 3 4 5 6 7 x\n", 1),
            "line 19: expected numbers, got 'x'",
        ),
        (
            HIERARCHY + HIERARCHY.replace("HIERARCHY\n", "") + MOTION,
            "line 16: expected 'MOTION' after the root's closing brace (one root only), got 'ROOT'",
        ),
    ],
    ids=[
        "no MOTION",
        "unknown channel",
        "OFFSET with two numbers",
        "unexpected keyword",
        "duplicate joint name",
        "unclosed joint",
        "short row",
        "fewer frames than declared",
        "frame time not a number",
        "frame time zero",
        "no Frames line",
        "value not a number",
        "two roots",
    ],
)
def test_malformed_files_raise_file_format_errors_naming_the_problem(tmp_path, text, message):
    path = tmp_path / "bad.bvh"
    path.write_text(text)

    with pytest.raises(FileFormatError, match=re.escape(message)) as error:
        read_bvh(path, scale=1.0)

    assert str(path) in str(error.value)


def test_the_well_formed_small_file_of_the_malformed_cases_reads(tmp_path):
    (tmp_path / "good.bvh").write_text(HIERARCHY + MOTION)

    motion = read_bvh(tmp_path / "good.bvh", scale=0.5).to_skeleton_motion()

    assert motion.names == ["hips", "knee", "knee_end"]
    np.testing.assert_allclose(motion.bone_lengths()[:, 1:], 2.0, atol=1e-12)
    np.testing.assert_allclose(motion.positions[:, 0], [[0.0, 0.5, 1.0]] * 2, atol=1e-12)


def write_small(tmp_path, **changes):
    rng = np.random.default_rng(3)
    arguments = {
        "names": ["a", "b"],
        "parents": np.array([-1, 0]),
        "offsets": np.zeros((2, 3)),
        "local_rotations": random_rotations(rng, (2, 2)),
        "root_positions": np.zeros((2, 3)),
        "frame_time": 0.01,
    }
    write_bvh(tmp_path / "out.bvh", **(arguments | changes))


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"local_rotations": np.ones((2, 2, 3, 3))}, "local_rotations: expected rotation matrices"),
        (
            {"local_rotations": -np.tile(np.eye(3), (2, 2, 1, 1))},
            "local_rotations: expected rotation matrices",
        ),
        ({"parents": np.array([-1, -1])}, "parents: expected exactly one root (-1), got 2"),
        ({"names": ["a", "b c"]}, "names: expected non-empty names without whitespace, got 'b c'"),
        (
            {"rotation_order": "XXY"},
            "rotation_order: expected three distinct letters among 'XYZ', got 'XXY'",
        ),
        (
            {"root_positions": np.zeros((3, 3))},
            "root_positions: expected finite values, shape (2, 3), got (3, 3)",
        ),
        (
            {"end_sites": {0: np.zeros(3)}},
            "end_sites: expected indices of joints without children, got 0",
        ),
        ({"frame_time": 0.0}, "frame_time: expected a positive number [s], got 0.0"),
    ],
    ids=[
        "not orthogonal",
        "a reflection",
        "two roots",
        "name with a space",
        "repeated axis",
        "wrong frame count",
        "end site on a parent",
        "zero frame time",
    ],
)
def test_bad_arguments_to_write_bvh_raise_input_errors_and_write_nothing(
    tmp_path, changes, message
):
    with pytest.raises(InputError, match=re.escape(message)):
        write_small(tmp_path, **changes)

    assert not list(tmp_path.iterdir())
