import json
import warnings

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.exceptions import IbikWarning, InputError, UnknownNameError
from ibik_pin.human import HUMAN_END_EFFECTORS, load_human
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.io.bvh import CMU_BVH_SCALE, read_bvh
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.masks import list_mask_files, read_mask
from ibik_pin.io.trc import read_trc
from ibik_pin.limits import JointLimits
from ibik_pin.subject.scaling import scale_human, segment_lengths_from_keypoints
from ibik_pin.synthetic.dataset import write_dataset
from ibik_pin.synthetic.defects import SilhouetteDefects, apply_defects
from ibik_pin.synthetic.mocap import (
    facing_directions,
    keypoints_from_motion,
    pose_model_to_keypoints,
)
from ibik_pin.synthetic.rig import humaneva_rig
from ibik_pin.synthetic.silhouettes import render_limb_masks, render_silhouettes
from ibik_pin.vision.camera import cameras_in_frame
from tests.paths import SHARED_DATA, TEST_DATA

SHARED = SHARED_DATA
needs_shared_data = pytest.mark.skipif(not SHARED.is_dir(), reason="the shared data is not beside the repository")


def read_bvh_quietly(path, scale):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IbikWarning)  # Boxing_Toes holds one frame more than declared
        return read_bvh(path, scale=scale).to_skeleton_motion()


EXCERPTS = {
    "asf": lambda: read_asf_amc(TEST_DATA / "35.asf", TEST_DATA / "35_01_excerpt.amc"),
    "boxing": lambda: read_bvh_quietly(TEST_DATA / "Boxing_Toes_excerpt.bvh", 0.01),
}
RECORDINGS = {
    "35_01.amc": ("asf", lambda: read_asf_amc(SHARED / "cmu" / "35.asf", SHARED / "cmu" / "35_01.amc")),
    "39_01.amc": ("asf", lambda: read_asf_amc(SHARED / "cmu" / "39.asf", SHARED / "cmu" / "39_01.amc")),
    "131_01.bvh": ("cmu_bvh", lambda: read_bvh_quietly(SHARED / "bvh" / "131_01.bvh", CMU_BVH_SCALE)),
    "01_01.bvh": ("cmu_bvh", lambda: read_bvh_quietly(SHARED / "bvh" / "01_01.bvh", CMU_BVH_SCALE)),
    "Boxing_Toes.bvh": ("boxing", lambda: read_bvh_quietly(SHARED / "bvh" / "Boxing_Toes.bvh", 0.01)),
}


@pytest.fixture(scope="module")
def walking():
    """The CMU walking excerpt's keypoints and the human scaled to them."""
    names, positions = keypoints_from_motion(EXCERPTS["asf"](), "asf")
    body = scale_human(load_human(), segment_lengths_from_keypoints(names, positions))
    return names, positions, body


@pytest.fixture(scope="module")
def posed_walking(walking):
    names, positions, body = walking
    q, residuals = pose_model_to_keypoints(body, names, positions[:10])
    return q, residuals


def assert_left_is_on_the_left(names, positions):
    """The facing direction from hips and shoulders agrees with where the feet point, and the
    sequence is Y up and starts with the subject facing +X, left at -Z."""
    facing = facing_directions(names, positions)
    for side in "LR":
        foot = positions[:, names.index(f"{side}BigToe")] - positions[:, names.index(f"{side}Ankle")]
        foot[:, 1] = 0.0
        flat = np.linalg.norm(foot, axis=1) > 0.1  # a foot pointing down says nothing
        assert flat.mean() > 0.5
        agreement = np.einsum("fi,fi->f", facing[flat], foot[flat]) > 0.0
        assert agreement.mean() > 0.95, side
    height = {name: np.median(positions[:, names.index(name), 1]) for name in ("Head", "Hip", "LAnkle")}
    assert height["Head"] > height["Hip"] > height["LAnkle"]
    assert facing[0] == pytest.approx([1.0, 0.0, 0.0], abs=1e-9)
    assert positions[0, names.index("LHip"), 2] < positions[0, names.index("RHip"), 2]
    assert positions[0, names.index("LShoulder"), 2] < positions[0, names.index("RShoulder"), 2]


@pytest.mark.parametrize("source", sorted(EXCERPTS))
def test_left_keypoints_are_on_the_subject_s_left_in_the_excerpts(source):
    names, positions = keypoints_from_motion(EXCERPTS[source](), source)
    assert positions.shape == (EXCERPTS[source]().positions.shape[0], len(names), 3)
    assert_left_is_on_the_left(names, positions)


@needs_shared_data
@pytest.mark.parametrize("recording", sorted(RECORDINGS))
def test_left_keypoints_are_on_the_subject_s_left_in_the_shared_recordings(recording):
    source, load = RECORDINGS[recording]
    names, positions = keypoints_from_motion(load(), source)
    assert_left_is_on_the_left(names, positions)


def test_the_walking_subject_walks_the_way_it_faces(walking):
    names, positions, _ = walking
    hip = positions[:, names.index("Hip")]
    velocity = np.gradient(hip, 1.0 / 120.0, axis=0)
    velocity[:, 1] = 0.0
    forward_speed = np.einsum("fi,fi->f", facing_directions(names, positions), velocity)
    assert np.all(forward_speed > 0.5)  # [m/s]


KEYPOINTS = ["Hip", "LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle", "LBigToe", "RBigToe",
             "Neck", "Head", "LShoulder", "RShoulder", "LElbow", "RElbow", "LWrist", "RWrist"]


@pytest.mark.parametrize("source", sorted(EXCERPTS))
def test_every_source_gives_the_same_keypoints(source):
    assert keypoints_from_motion(EXCERPTS[source](), source)[0] == KEYPOINTS


@needs_shared_data
def test_both_cmu_bvh_namings_give_the_same_keypoints_and_segment_lengths():
    lengths = {}
    for recording in ("131_01.bvh", "01_01.bvh"):
        names, positions = keypoints_from_motion(RECORDINGS[recording][1](), "cmu_bvh")
        assert names == KEYPOINTS
        lengths[recording] = segment_lengths_from_keypoints(names, positions)
    # two adults: every segment in a human range, the two within 30 % of each other
    for name, value in lengths["131_01.bvh"].items():
        assert 0.6 < value / lengths["01_01.bvh"][name] < 1.4 or name == "pelvis_height", name
    assert 0.35 < lengths["01_01.bvh"]["left_thigh"] < 0.5


def test_an_unknown_source_or_a_missing_joint_is_named():
    motion = EXCERPTS["boxing"]()
    with pytest.raises(UnknownNameError, match="unknown source 'c3d'; known: asf, cmu_bvh, boxing"):
        keypoints_from_motion(motion, "c3d")
    with pytest.raises(UnknownNameError, match=r"joint.*'LeftHip'.*absent.*the motion's joints: root"):
        keypoints_from_motion(EXCERPTS["asf"](), "cmu_bvh")


def test_posing_ten_frames_of_real_walking_fits_every_keypoint_within_3_cm(walking, posed_walking):
    _, _, body = walking
    q, residuals = posed_walking
    assert q.shape == (10, body.model.nq)
    assert residuals.shape == (10,)
    assert residuals.mean() < 0.03  # measured: 3 mm
    limits = JointLimits(body.model)
    assert max(limits.violation(q_frame) for q_frame in q) < 1e-9


def test_posing_starts_from_any_heading(walking):
    names, positions, body = walking
    turned = positions[:3] @ np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]).T  # faces -X
    _, residuals = pose_model_to_keypoints(body, names, turned)
    assert residuals.max() < 0.03


def test_posing_skips_a_missing_keypoint(walking):
    names, positions, body = walking
    holed = positions[:3].copy()
    holed[1, names.index("LElbow")] = np.nan
    _, residuals = pose_model_to_keypoints(body, names, holed)
    assert np.all(np.isfinite(residuals)) and residuals.max() < 0.03


def test_the_rig_s_cameras_see_the_whole_subject(walking):
    names, positions, _ = walking
    center = positions[:, names.index("Hip")].mean(axis=0)
    cameras = humaneva_rig(4, center, distance_m=4.0, seed=3)
    assert [camera.name for camera in cameras] == ["cam1", "cam2", "cam3", "cam4"]
    points = positions.reshape(-1, 3)
    for camera in cameras:
        projection = camera.project_with_jacobian(points)
        assert np.all(projection.depth > 0.0)
        assert np.all(camera.contains(projection.pixels))
        assert np.linalg.norm((camera.center_world - center)[[0, 2]]) == pytest.approx(4.0)
        assert camera.center_world[1] == pytest.approx(1.5)
        assert np.all(camera.distortion == 0.0)


def test_the_rig_spreads_its_azimuths_and_repeats_with_its_seed():
    cameras = humaneva_rig(3, np.array([0.0, 0.9, 0.0]), seed=7, jitter_deg=15.0)
    azimuths = np.sort([np.arctan2(c.center_world[2], c.center_world[0]) % (2 * np.pi) for c in cameras])
    gaps = np.diff(np.append(azimuths, azimuths[0] + 2 * np.pi))
    assert np.all(np.abs(np.rad2deg(gaps) - 120.0) <= 30.0 + 1e-9)
    again = humaneva_rig(3, np.array([0.0, 0.9, 0.0]), seed=7, jitter_deg=15.0)
    assert all(np.array_equal(a.rotation, b.rotation) for a, b in zip(cameras, again, strict=True))
    other = humaneva_rig(3, np.array([0.0, 0.9, 0.0]), seed=8)
    assert not np.allclose(cameras[0].rotation, other[0].rotation)


def test_the_rig_refuses_a_bad_count_or_distance():
    with pytest.raises(InputError, match="n_views: expected a positive integer, got 0"):
        humaneva_rig(0, np.zeros(3))
    with pytest.raises(InputError, match="distance_m: expected a positive distance"):
        humaneva_rig(2, np.zeros(3), distance_m=-1.0)


def segment_end_pixels(body, q, camera):
    """Pixels (N, 2) of the keypoints the capsules are drawn along, and the Head."""
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, q)
    names = sorted({name for segment in body.segments for name in segment} | {"Head"})
    return camera.project(np.array([data.oMf[body.frame_id(name)].translation for name in names]))


def covers(mask, pixels):
    rows, columns = np.rint(pixels[:, 1]).astype(int), np.rint(pixels[:, 0]).astype(int)
    return mask[rows, columns]


def test_rendered_silhouettes_cover_the_projected_keypoints(walking, posed_walking):
    names, positions, body = walking
    q, _ = posed_walking
    cameras = humaneva_rig(2, positions[:, names.index("Hip")].mean(axis=0), seed=1)
    masks = render_silhouettes(body, q[0], cameras)
    for camera, mask in zip(cameras, masks, strict=True):
        assert mask.shape == (480, 640) and mask.dtype == bool
        assert 2000 < mask.sum() < 0.3 * mask.size
        assert np.all(covers(mask, segment_end_pixels(body, q[0], camera)))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, walking, posed_walking):
    names, positions, body = walking
    q, _ = posed_walking
    q = q[:4]
    cameras = humaneva_rig(3, positions[:, names.index("Hip")].mean(axis=0), seed=2)
    folder = tmp_path_factory.mktemp("dataset")
    paths = write_dataset(folder, body, q, cameras, 120.0, HUMAN_END_EFFECTORS, seed=5)
    return paths, body, q, cameras


def test_the_written_calibration_projects_model_frame_points_to_the_same_pixels(dataset):
    paths, _, _, cameras = dataset
    read_back = cameras_in_frame(read_calibration(paths.calibration), POSE2SIM_TRC_TO_WORLD)
    points = read_trc(paths.truth).positions.reshape(-1, 3)
    assert [camera.name for camera in read_back] == [camera.name for camera in cameras]
    for original, camera in zip(cameras, read_back, strict=True):
        assert np.abs(camera.project(points) - original.project(points)).max() < 1e-6
    # the calibration's world is Pose2Sim's, Z up: the cameras stand 1.5 m up its Z axis
    plain = read_calibration(paths.calibration)
    assert all(camera.center_world[2] == pytest.approx(1.5) for camera in plain)


def test_the_written_trc_files_hold_the_truth_and_the_targets(dataset):
    paths, body, q, _ = dataset
    truth = read_trc(paths.truth)
    targets = read_trc(paths.targets)
    assert truth.marker_names == list(body.keypoints)
    assert targets.marker_names == HUMAN_END_EFFECTORS
    assert truth.units == targets.units == "m" and truth.data_rate == 120.0
    assert np.allclose(truth.times, np.arange(4) / 120.0)
    data = body.model.createData()
    for frame, q_frame in enumerate(q):
        pin.framesForwardKinematics(body.model, data, q_frame)
        expected = np.array([data.oMf[body.frame_id(name)].translation for name in truth.marker_names])
        assert np.abs(truth.positions[frame] - expected).max() < 1e-6
    indices = [truth.marker_names.index(name) for name in HUMAN_END_EFFECTORS]
    assert np.abs(targets.positions - truth.positions[:, indices]).max() < 1e-6  # noise_mm = 0
    assert np.array_equal(np.load(paths.truth_q), q)
    metadata = json.loads(paths.metadata.read_text())
    assert metadata["frames"] == 4 and metadata["cameras"] == ["cam1", "cam2", "cam3"]


def test_the_written_masks_are_the_rendered_silhouettes(dataset):
    paths, body, q, cameras = dataset
    for camera in cameras:
        files = list_mask_files(paths.masks / camera.name)
        assert [f.name for f in files] == [f"{i:06d}.png" for i in range(4)]
    for frame, q_frame in enumerate(q):
        rendered = render_silhouettes(body, q_frame, cameras)
        for camera, expected in zip(cameras, rendered, strict=True):
            mask = read_mask(paths.masks / camera.name / f"{frame:06d}.png", camera.size)
            assert np.array_equal(mask, expected)
            assert mask.any()
            assert np.all(covers(mask, segment_end_pixels(body, q_frame, camera)))


def test_target_noise_has_the_requested_spread_and_repeats_with_the_seed(tmp_path, walking, posed_walking):
    _, _, body = walking
    q = np.repeat(posed_walking[0][:1], 200, axis=0)
    camera = humaneva_rig(1, q[0, :3], seed=0)
    first = write_dataset(tmp_path / "a", body, q, camera, 100.0, ["LWrist", "RWrist"], noise_mm=5.0, seed=9)
    second = write_dataset(tmp_path / "b", body, q, camera, 100.0, ["LWrist", "RWrist"], noise_mm=5.0, seed=9)
    truth = read_trc(first.truth)
    targets = read_trc(first.targets)
    noise = targets.positions - truth.positions[:, [truth.marker_names.index(n) for n in ("LWrist", "RWrist")]]
    assert np.std(noise) == pytest.approx(5e-3, rel=0.1)
    assert abs(np.mean(noise)) < 1e-3
    assert np.array_equal(read_trc(second.targets).positions, targets.positions)


def test_write_dataset_refuses_an_unknown_target(tmp_path, walking, posed_walking):
    _, _, body = walking
    camera = humaneva_rig(1, np.zeros(3))
    with pytest.raises(UnknownNameError, match=r"unknown keypoint.*'LeftHand'"):
        write_dataset(tmp_path, body, posed_walking[0][:1], camera, 100.0, ["LeftHand"])


# --- Defects -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def silhouette(walking, posed_walking):
    names, positions, body = walking
    camera = humaneva_rig(1, positions[:, names.index("Hip")].mean(axis=0), seed=4)[0]
    q = posed_walking[0][0]
    return render_silhouettes(body, q, [camera])[0], render_limb_masks(body, q, camera)


def test_erosion_shrinks_the_silhouette(silhouette, rng):
    mask, _ = silhouette
    eroded = apply_defects(mask, SilhouetteDefects(erode_px=2), rng)
    assert eroded.sum() < mask.sum() and not np.any(eroded & ~mask)


def test_dilation_grows_the_silhouette(silhouette, rng):
    mask, _ = silhouette
    dilated = apply_defects(mask, SilhouetteDefects(dilate_px=2), rng)
    assert dilated.sum() > mask.sum() and not np.any(mask & ~dilated)


def test_holes_remove_pixels_inside(silhouette, rng):
    mask, _ = silhouette
    holed = apply_defects(mask, SilhouetteDefects(holes=3, hole_radius_px=3.0), rng)
    assert holed.sum() < mask.sum() and not np.any(holed & ~mask)


def test_blobs_add_pixels(silhouette, rng):
    mask, _ = silhouette
    for attached in (0.0, 1.0):
        blobbed = apply_defects(mask, SilhouetteDefects(blobs=2, blob_radius_px=10.0,
                                                        attached_blob_probability=attached), rng)
        assert blobbed.sum() > mask.sum() and not np.any(mask & ~blobbed)


def test_a_missing_limb_removes_exactly_one_limb_s_own_pixels(silhouette, rng):
    mask, limbs = silhouette
    assert len(limbs) == 4 and all(limb.any() for limb in limbs)
    lost = apply_defects(mask, SilhouetteDefects(missing_limb_probability=1.0), rng, limbs)
    removed = mask & ~lost
    assert not np.any(lost & ~mask)
    assert any(np.array_equal(removed, limb & mask) for limb in limbs)
    assert np.array_equal(apply_defects(mask, SilhouetteDefects(missing_limb_probability=0.0), rng, limbs), mask)


def test_no_defect_leaves_the_mask_and_the_input_is_never_modified(silhouette, rng):
    mask, _ = silhouette
    before = mask.copy()
    assert np.array_equal(apply_defects(mask, SilhouetteDefects(), rng), mask)
    apply_defects(mask, SilhouetteDefects(erode_px=3, holes=2, blobs=2), rng)
    assert np.array_equal(mask, before)


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"erode_px": -1}, "erode_px: expected a non-negative integer"),
        ({"holes": 1.5}, "holes: expected a non-negative integer"),
        ({"blob_radius_px": 0.0}, "blob_radius_px: expected a positive radius"),
        ({"missing_limb_probability": 1.5}, r"missing_limb_probability: expected a probability in \[0, 1\]"),
    ],
)
def test_defects_refuse_impossible_values(arguments, message):
    with pytest.raises(InputError, match=message):
        SilhouetteDefects(**arguments)


def test_a_dataset_with_defects_repeats_with_its_seed(tmp_path, walking, posed_walking):
    names, positions, body = walking
    q = posed_walking[0][:2]
    cameras = humaneva_rig(2, positions[:, names.index("Hip")].mean(axis=0), seed=0)
    defects = SilhouetteDefects(erode_px=1, holes=2, blobs=2, missing_limb_probability=0.5)
    first = write_dataset(tmp_path / "a", body, q, cameras, 120.0, ["Hip"], defects=defects, seed=3)
    second = write_dataset(tmp_path / "b", body, q, cameras, 120.0, ["Hip"], defects=defects, seed=3)
    clean = render_silhouettes(body, q[1], cameras)
    for camera, rendered in zip(cameras, clean, strict=True):
        a = read_mask(first.masks / camera.name / "000001.png")
        assert np.array_equal(a, read_mask(second.masks / camera.name / "000001.png"))
        assert not np.array_equal(a, rendered)
