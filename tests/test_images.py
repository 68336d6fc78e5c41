"""Tests of ibik_pin.images: support images and their interpolation, masks, videos, silhouettes."""

import itertools
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from ibik_pin.app.silhouette_files import silhouettes_from_video
from ibik_pin.exceptions import EmptySilhouetteWarning, FileFormatError, InputError
from ibik_pin.io.masks import list_mask_files, read_mask
from ibik_pin.io.video import VideoReader
from ibik_pin.vision.segmentation import TemporalMajority
from ibik_pin.vision.support import SupportImage, obstacle_support, support_from_mask
from tests.paths import SHARED_DATA

DEMO_VIDEO = SHARED_DATA / "pose2sim_demo" / "videos" / "cam01.mp4"
VIDEO_SIZE = (160, 120)  # (w, h) [px]
VIDEO_FRAMES = 30
DISC_RADIUS = 15  # [px]


def disc_mask(size: tuple[int, int], centre: tuple[int, int], radius: int) -> np.ndarray:
    mask = np.zeros((size[1], size[0]), np.uint8)
    cv2.circle(mask, centre, radius, 1, -1)
    return mask.astype(bool)


def disc_centre(frame: int) -> tuple[int, int]:
    return 20 + 4 * frame, int(60 + 20 * np.sin(frame / 5))


def textured_background(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = rng.integers(0, 256, (VIDEO_SIZE[1], VIDEO_SIZE[0], 3)).astype(np.uint8)
    return cv2.normalize(cv2.GaussianBlur(noise, (0, 0), 2.0), None, 40, 160, cv2.NORM_MINMAX)


def write_video(path: Path, frames) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, VIDEO_SIZE)
    assert writer.isOpened()
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


@pytest.fixture(scope="module")
def disc_video(tmp_path_factory):
    """A bright disc moving over a static textured background, its true masks and the background."""
    background = textured_background(seed=0)
    frames, truth = [], []
    for index in range(VIDEO_FRAMES):
        frame = background.copy()
        cv2.circle(frame, disc_centre(index), DISC_RADIUS, (240, 240, 240), -1)
        frames.append(frame)
        truth.append(disc_mask(VIDEO_SIZE, disc_centre(index), DISC_RADIUS))
    folder = tmp_path_factory.mktemp("video")
    path = write_video(folder / "disc.mp4", frames)
    background_path = folder / "background.png"
    cv2.imwrite(str(background_path), background)
    return path, truth, background_path


def intersection_over_union(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.count_nonzero(a & b) / np.count_nonzero(a | b))


def random_support(seed: int, shape=(12, 17)) -> SupportImage:
    return SupportImage(np.random.default_rng(seed).normal(size=shape).astype(np.float32))


def test_support_sample_reads_pixel_centres_exactly_and_interpolates_bilinearly():
    support = random_support(seed=0)
    values = support.values.astype(np.float64)
    sampled, _ = support.sample(np.array([[3.0, 5.0], [16.0, 11.0], [3.5, 5.5]]))
    expected_mid = values[5:7, 3:5].mean()
    np.testing.assert_allclose(sampled, [values[5, 3], values[11, 16], expected_mid], rtol=0.0, atol=1e-12)


def test_support_gradient_matches_finite_differences_inside_cells_to_1e9():
    support = random_support(seed=1)
    rng = np.random.default_rng(2)
    cells = rng.integers([0, 0], [16, 11], size=(300, 2))
    pixels = cells + rng.uniform(0.05, 0.95, size=(300, 2))
    _, gradient = support.sample(pixels)
    step = 1e-3  # [px]; the interpolant is linear along each axis within a cell
    for axis in range(2):
        offset = np.zeros(2)
        offset[axis] = step
        ahead, behind = support.sample(pixels + offset).values, support.sample(pixels - offset).values
        finite_difference = (ahead - behind) / (2 * step)
        np.testing.assert_allclose(gradient[:, axis], finite_difference, rtol=0.0, atol=1e-9)


def test_support_sample_clamps_outside_points_to_the_border_with_zero_gradient_along_clamped_axes():
    support = random_support(seed=3)
    pixels = np.array([[-4.0, 2.25], [20.0, 2.25], [5.5, -1.0], [0.0, 2.25]])
    values, gradient = support.sample(pixels)
    border, border_gradient = support.sample(np.array([[0.0, 2.25], [16.0, 2.25], [5.5, 0.0]]))
    np.testing.assert_allclose(values[:3], border, rtol=0.0, atol=1e-12)
    assert gradient[0, 0] == 0.0 and gradient[1, 0] == 0.0 and gradient[2, 1] == 0.0
    np.testing.assert_allclose(gradient[:2, 1], border_gradient[:2, 1], rtol=0.0, atol=1e-12)
    assert gradient[3, 0] != 0.0
    np.testing.assert_array_equal(support.sample_mask(pixels), [False, False, False, True])


def test_support_sample_clamps_infinite_pixels_and_rejects_nan():
    support = random_support(seed=4)
    values, gradient = support.sample(np.array([[np.inf, 0.0]]))
    assert values[0] == support.values[0, -1] and gradient[0, 0] == 0.0
    with pytest.raises(InputError, match=r"pixels: expected coordinates that are not NaN, found 1 row\(s\) with NaN"):
        support.sample(np.array([[1.0, 2.0], [np.nan, 0.0]]))


def test_support_from_mask_is_positive_inside_capped_and_minus_the_distance_outside():
    mask = disc_mask((100, 80), (50, 40), 20)
    support = support_from_mask(mask, inside_cap_px=6.0, smooth_sigma_px=0.0)
    assert support.enabled and support.values.dtype == np.float32
    assert support.values[mask].min() > 0.0 and support.values.max() == pytest.approx(6.0, abs=1e-6)
    assert support.values[~mask].max() < 0.0
    # 10 px right of the disc's border (border halfway between pixel 70 and 71).
    assert support.values[40, 80] == pytest.approx(-(80 - 70.5), abs=0.5)
    uncapped = support_from_mask(mask, inside_cap_px=None, smooth_sigma_px=0.0)
    assert uncapped.values[40, 50] == pytest.approx(20.0, abs=1.0)


def test_support_from_mask_gradient_points_toward_the_body_outside_it():
    support = support_from_mask(disc_mask((100, 80), (50, 40), 10))
    _, gradient = support.sample(np.array([[80.3, 40.2], [50.1, 5.4]]))
    assert gradient[0, 0] < -0.5 and gradient[1, 1] > 0.5


def test_support_from_mask_truncates_the_outside_distance():
    support = support_from_mask(disc_mask((100, 80), (50, 40), 10), outside_cap_px=5.0, smooth_sigma_px=0.0)
    assert support.values.min() == pytest.approx(-5.0, abs=1e-6)


def test_an_empty_silhouette_warns_and_disables_the_view():
    with pytest.warns(EmptySilhouetteWarning, match=r"silhouette of size \(w, h\) = \(30, 20\) is empty"):
        support = support_from_mask(np.zeros((20, 30), bool))
    assert not support.enabled
    np.testing.assert_array_equal(support.values, 0.0)


def test_a_full_silhouette_is_inside_everywhere():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        support = support_from_mask(np.ones((20, 30), np.uint8))
    np.testing.assert_array_equal(support.values, 6.0)


def test_support_from_mask_rejects_a_mask_of_the_wrong_dtype_or_dimensions():
    with pytest.raises(InputError, match=r"mask: expected dtype bool or uint8 \(non-zero = set\), found dtype float64"):
        support_from_mask(np.zeros((4, 4)))
    with pytest.raises(InputError, match=r"mask: expected a 2D \(H, W\) array, found shape \(4, 4, 3\)"):
        support_from_mask(np.zeros((4, 4, 3), np.uint8))


def test_obstacle_support_is_zero_far_away_and_decreases_into_the_object():
    object_mask = np.zeros((60, 100), bool)
    object_mask[20:40, 40:60] = True
    support = obstacle_support(object_mask, influence_px=15.0)
    row = support.values[30].astype(np.float64)
    assert np.all(row[:20] == 0.0) and np.all(row[80:] == 0.0)
    assert np.all(np.diff(row[:50]) <= 0.0)  # from far left into the middle of the object
    assert row[50] < -15.0 and row[35] < 0.0
    assert row[24] == pytest.approx(0.0, abs=0.1)


def test_obstacle_support_adds_to_a_silhouette_support():
    mask = disc_mask((100, 60), (30, 30), 15)
    object_mask = np.zeros((60, 100), bool)
    object_mask[25:35, 70:80] = True
    total = support_from_mask(mask) + obstacle_support(object_mask, 10.0)
    silhouette = support_from_mask(mask)
    # OpenCV's blur may differ by one float32 ulp between calls (alignment-dependent SIMD).
    np.testing.assert_allclose(total.values[:, :40], silhouette.values[:, :40], rtol=1e-6, atol=1e-6)
    assert total.values[30, 75] < silhouette.values[30, 75] - 10.0
    expected = r"other: expected a support image of size \(w, h\) = \(100, 60\), found \(10, 10\)"
    with pytest.raises(InputError, match=expected):
        _ = silhouette + SupportImage(np.zeros((10, 10)))


def test_adding_to_a_disabled_support_keeps_the_view_disabled():
    with pytest.warns(EmptySilhouetteWarning):
        empty = support_from_mask(np.zeros((10, 10), bool))
    assert not (empty + SupportImage(np.ones((10, 10)))).enabled


def test_read_mask_reads_0_255_and_0_1_masks(tmp_path):
    mask = disc_mask((40, 30), (20, 15), 8)
    cv2.imwrite(str(tmp_path / "a.png"), mask.astype(np.uint8) * 255)
    cv2.imwrite(str(tmp_path / "b.png"), mask.astype(np.uint8))
    np.testing.assert_array_equal(read_mask(tmp_path / "a.png", expected_size=(40, 30)), mask)
    np.testing.assert_array_equal(read_mask(tmp_path / "b.png"), mask)


def test_read_mask_names_the_file_and_both_sizes_on_a_size_mismatch(tmp_path):
    cv2.imwrite(str(tmp_path / "mask.png"), np.zeros((30, 40), np.uint8))
    expected = r"mask\.png': expected size \(w, h\) = \(64, 48\), found \(w, h\) = \(40, 30\)"
    with pytest.raises(InputError, match=expected):
        read_mask(tmp_path / "mask.png", expected_size=(64, 48))


def test_read_mask_reports_an_unreadable_or_missing_image(tmp_path):
    (tmp_path / "fake.png").write_text("not an image")
    with pytest.raises(FileFormatError, match=r"fake\.png': expected a readable image, OpenCV cannot decode it"):
        read_mask(tmp_path / "fake.png")
    with pytest.raises(FileFormatError, match=r"absent\.png': expected a readable image, found no such file"):
        read_mask(tmp_path / "absent.png")


def test_list_mask_files_sorts_image_files_by_name_with_numbers_as_numbers(tmp_path):
    for name in ["frame10.png", "frame2.PNG", "frame1.jpg", "notes.txt", "frame3.tiff"]:
        (tmp_path / name).write_bytes(b"")
    names = [path.name for path in list_mask_files(tmp_path)]
    assert names == ["frame1.jpg", "frame2.PNG", "frame3.tiff", "frame10.png"]


def test_list_mask_files_reports_a_folder_without_images(tmp_path):
    (tmp_path / "notes.txt").write_text("")
    with pytest.raises(FileFormatError, match=r"expected image files .*found none"):
        list_mask_files(tmp_path)


def test_video_reader_iterates_all_frames_each_time(disc_video):
    path, _, _ = disc_video
    with VideoReader(path) as reader:
        assert reader.size == VIDEO_SIZE and reader.frame_count == VIDEO_FRAMES
        first = list(reader)
        second = list(itertools.islice(reader, 3))
    assert len(first) == VIDEO_FRAMES and first[0].shape == (120, 160, 3) and first[0].dtype == np.uint8
    np.testing.assert_array_equal(second[2], first[2])


def test_video_reader_reports_an_unreadable_video(tmp_path):
    (tmp_path / "fake.mp4").write_text("not a video")
    with pytest.raises(FileFormatError, match=r"fake\.mp4': expected a video OpenCV can decode"):
        VideoReader(tmp_path / "fake.mp4")
    with pytest.raises(FileFormatError, match=r"absent\.mp4': expected a readable video, found no such file"):
        VideoReader(tmp_path / "absent.mp4")


def test_silhouettes_from_the_video_itself_overlap_the_moving_disc(disc_video):
    path, truth, _ = disc_video
    masks = silhouettes_from_video(path)
    assert len(masks) == VIDEO_FRAMES and masks[0].dtype == bool and masks[0].shape == (120, 160)
    overlaps = [intersection_over_union(mask, true) for mask, true in zip(masks, truth, strict=True)]
    assert min(overlaps) > 0.8


def test_silhouettes_learned_on_a_background_image_overlap_the_moving_disc(disc_video):
    path, truth, background_path = disc_video
    masks = silhouettes_from_video(path, [background_path], max_frames=12)
    assert len(masks) == 12
    overlaps = [intersection_over_union(mask, true) for mask, true in zip(masks, truth[:12], strict=True)]
    assert min(overlaps) > 0.8


def test_silhouettes_reject_a_background_of_another_size(disc_video, tmp_path):
    path, _, _ = disc_video
    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((10, 10, 3), np.uint8))
    expected = r"small\.png': expected the video's size \(w, h\) = \(160, 120\), found \(w, h\) = \(10, 10\)"
    with pytest.raises(InputError, match=expected):
        silhouettes_from_video(path, [tmp_path / "small.png"])


@pytest.mark.skipif(not DEMO_VIDEO.exists(), reason="Pose2Sim demo video not available")
def test_the_first_frames_of_the_pose2sim_demo_video_are_read():
    with VideoReader(DEMO_VIDEO) as reader:
        frames = list(itertools.islice(reader, 3))
        size = reader.size
    assert size == (1080, 1920)
    assert len(frames) == 3 and frames[0].shape == (1920, 1080, 3) and frames[0].dtype == np.uint8
    masks = silhouettes_from_video(DEMO_VIDEO, max_frames=4)
    assert len(masks) == 4 and masks[0].shape == (1920, 1080)


def flickering_sequence(frames: int = 7):
    """A disc moving 1 px per frame in two cameras; frame 3 of camera 0 has a hole and a blob."""
    masks = []
    for frame in range(frames):
        views = [disc_mask((80, 60), (30 + frame, 30), 12), disc_mask((90, 70), (40, 35 - frame), 10)]
        if frame == 3:
            views[0] = views[0].copy()
            views[0][27:33, 27:33] = False  # a hole in the body
            views[0][5:12, 60:70] = True  # a shadow away from it
        masks.append(views)
    return masks


def test_temporal_majority_votes_away_one_frame_flicker_and_keeps_the_motion():
    masks = flickering_sequence()
    filtered = TemporalMajority(lambda frame: masks[frame], len(masks), radius=1)
    clean_frame_3 = disc_mask((80, 60), (33, 30), 12)
    result = filtered(3)
    assert len(result) == 2 and result[0].dtype == np.bool_
    # The hole and the blob are gone; only the disc's edge, shifted 1 px a frame, may differ.
    assert result[0][27:33, 27:33].all() and not result[0][5:12, 60:70].any()
    assert np.count_nonzero(result[0] ^ clean_frame_3) <= 2 * 2 * 12
    assert intersection_over_union(result[1], masks[3][1]) > 0.9
    # The ends repeat the first and last frames: a clean sequence end is itself.
    np.testing.assert_array_equal(filtered(0)[1], masks[0][1])
    np.testing.assert_array_equal(filtered(6)[0], masks[6][0])


def test_temporal_majority_reads_each_frame_once_in_order():
    masks = flickering_sequence()
    reads = []

    def source(frame):
        reads.append(frame)
        return masks[frame]

    filtered = TemporalMajority(source, len(masks), radius=2)
    for frame in range(len(masks)):
        filtered(frame)
    assert reads == list(range(len(masks)))


@pytest.mark.parametrize("radius", [0, -1, 1.5, True])
def test_temporal_majority_rejects_a_radius_that_is_not_a_positive_whole_number(radius):
    with pytest.raises(InputError, match="radius"):
        TemporalMajority(lambda frame: [], 5, radius=radius)


def test_sampling_equals_a_plain_bilinear_reading_inside_and_outside_the_image():
    """The one-gather interpolation against the four corners read one point at a time, on seeded
    points inside, on the border, beyond it and at infinity, for images down to one pixel wide."""
    rng = np.random.default_rng(8)
    for height, width in [(48, 64), (1, 5), (5, 1), (1, 1), (2, 2)]:
        values = rng.normal(size=(height, width)).astype(np.float32)
        pixels = np.column_stack([rng.uniform(-3.0, width + 2.0, 60), rng.uniform(-3.0, height + 2.0, 60)])
        pixels[:5, 0], pixels[5:10, 1], pixels[10] = np.inf, -np.inf, [width - 1, height - 1]
        sample = SupportImage(values).sample(pixels)
        for (u, v), value, gradient in zip(pixels, sample.values, sample.gradient, strict=True):
            cu, cv = min(max(u, 0.0), width - 1), min(max(v, 0.0), height - 1)
            c0, r0 = min(int(cu), max(width - 2, 0)), min(int(cv), max(height - 2, 0))
            c1, r1 = min(c0 + 1, width - 1), min(r0 + 1, height - 1)
            a, b, c, d = (float(values[r, c]) for r, c in [(r0, c0), (r0, c1), (r1, c0), (r1, c1)])
            fu, fv = cu - c0, cv - r0
            top, bottom = a + fu * (b - a), c + fu * (d - c)
            assert value == pytest.approx(top + fv * (bottom - top), abs=1e-12)
            expected = [((1 - fv) * (b - a) + fv * (d - c)) * (0.0 <= u <= width - 1),
                        (bottom - top) * (0.0 <= v <= height - 1)]
            np.testing.assert_allclose(gradient, expected, atol=1e-12)
