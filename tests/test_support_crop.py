"""Distance transforms over the silhouette's bounding box only give what the whole frame gives."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.vision.distance import box_around, distance_to_background, scan_mask, signed_distance
from ibik_pin.vision.medial_axis import medial_axis_pixels
from ibik_pin.vision.support import SupportImage, support_from_mask
from ibik_pin.vision.support_window import SILHOUETTE_MARGIN_PX, TARGETS_MARGIN_PX


def random_silhouettes(seed: int, count: int, size=(120, 160)):
    """Ellipse unions, some cut by the image's edges (seeded)."""
    rng = np.random.default_rng(seed)
    height, width = size
    for _ in range(count):
        mask = np.zeros(size, np.uint8)
        for _ in range(int(rng.integers(1, 5))):
            centre = (int(rng.integers(-10, width + 10)), int(rng.integers(-10, height + 10)))
            axes = (int(rng.integers(2, 40)), int(rng.integers(2, 40)))
            cv2.ellipse(mask, centre, axes, float(rng.uniform(0.0, 180.0)), 0, 360, 1, -1)
        if mask.any() and not mask.all():
            yield mask


def whole_framesigned_distance(mask: np.ndarray) -> np.ndarray:
    mask_u8 = mask.astype(np.uint8)
    inside, outside = distance_to_background(mask_u8), distance_to_background(1 - mask_u8)
    return np.where(mask.astype(bool), inside - 0.5, 0.5 - outside).astype(np.float32)


def test_the_signed_distance_from_the_bounding_box_equals_the_whole_frames():
    masks = list(random_silhouettes(seed=3, count=150))
    assert len(masks) > 100
    for mask in masks:
        assert np.array_equal(signed_distance(mask.astype(bool)), whole_framesigned_distance(mask))


def test_the_signed_distance_capped_in_its_compiled_call_equals_numpys_cap_of_the_whole_frame():
    for mask in random_silhouettes(seed=8, count=60):
        expected = whole_framesigned_distance(mask)
        np.minimum(expected, np.float32(2.5), out=expected)
        assert np.array_equal(signed_distance(mask.astype(bool), inside_cap_px=2.5), expected)
        assert np.array_equal(signed_distance(mask, inside_cap_px=2.5), expected)  # uint8 0/1 as well


@pytest.mark.parametrize("dtype", [np.bool_, np.uint8])
def test_a_scanned_mask_is_the_masks_copy_its_count_and_its_bounding_box(dtype):
    rng = np.random.default_rng(9)
    masks = [mask * np.uint8(rng.integers(1, 256)) for mask in random_silhouettes(seed=9, count=40)]
    masks += [np.zeros((7, 5), np.uint8), np.ones((3, 4), np.uint8), np.eye(6, 9, 2, dtype=np.uint8)]
    for mask in masks:
        mask = (mask != 0) if dtype == np.bool_ else mask
        strided = mask[::2, 1::3]  # a view that is not contiguous
        for image in (mask, strided):
            scanned = scan_mask(image)
            assert np.array_equal(scanned.mask, image != 0) and scanned.mask.dtype == np.bool_
            assert scanned.mask is not image and not np.shares_memory(scanned.mask, image)
            assert scanned.set_pixels == np.count_nonzero(image)
            assert scanned.box == (box_around(image != 0) if image.any() else None)


def test_scanning_refuses_what_as_mask_refuses():
    for bad in ([[1, 0]], np.zeros((2, 2), np.float32), np.zeros(4, np.uint8), np.zeros((0, 3), np.bool_)):
        with pytest.raises(InputError):
            scan_mask(bad)


def test_the_exact_distance_does_not_depend_on_the_part_of_the_image_transformed():
    for mask in random_silhouettes(seed=4, count=50):
        rows = np.flatnonzero(mask.any(axis=1))
        columns = np.flatnonzero(mask.any(axis=0))
        grown = (slice(max(rows[0] - 1, 0), rows[-1] + 2), slice(max(columns[0] - 1, 0), columns[-1] + 2))
        assert np.array_equal(distance_to_background(mask)[grown], distance_to_background(mask[grown]))


@pytest.mark.parametrize("seed", [5, 6])
def test_the_medial_axis_from_the_bounding_box_equals_the_whole_frames(seed):
    # Two lone pixels in opposite corners stretch the bounding box over the whole frame without
    # touching the ridge (they are 1 px deep, under min_depth_px): the whole-frame path, to compare.
    checked = 0
    for mask in random_silhouettes(seed=seed, count=120):
        if mask[:4, :4].any() or mask[-4:, -4:].any():
            continue
        whole = mask.copy()
        whole[0, 0] = whole[-1, -1] = 1
        assert np.array_equal(medial_axis_pixels(mask), medial_axis_pixels(whole))
        checked += 1
    assert checked > 50


def opencv_distances(image: np.ndarray) -> np.ndarray:
    """OpenCV's precise Euclidean transform, squared and rounded to whole pixels^2 in float64."""
    raw = cv2.distanceTransform(image, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.sqrt(np.rint(np.square(raw, dtype=np.float64))).astype(np.float32)


def test_the_compiled_transform_equals_opencvs_up_to_the_largest_frame():
    """On seeded silhouettes, random speckle of every density and size down to one pixel, and
    640 x 480 frames whose only zero pixels are far apart (distances to 800 px)."""
    images = [1 - mask for mask in random_silhouettes(seed=5, count=30)]
    rng = np.random.default_rng(6)
    for _ in range(5):
        image = np.ones((480, 640), np.uint8)
        image[rng.integers(0, 480, 2), rng.integers(0, 640, 2)] = 0
        images.append(image)
    for _ in range(200):
        height, width = rng.integers(1, 40, 2)
        image = (rng.random((height, width)) < rng.uniform(0.0, 1.0)).astype(np.uint8)
        image.flat[rng.integers(image.size)] = 0
        images.append(image)
    for image in images:
        assert np.array_equal(distance_to_background(image), opencv_distances(image))
        assert np.array_equal(distance_to_background(image.astype(bool)), opencv_distances(image))


def test_an_image_without_a_zero_pixel_is_infinitely_far_from_one():
    assert np.all(np.isinf(distance_to_background(np.ones((3, 5), np.uint8))))
    # Any numbers: non-zero is set (256 stays set, not wrapped to 0 as a uint8 cast would).
    assert np.all(np.isinf(distance_to_background(np.full((2, 3), 256, np.int32))))
    assert distance_to_background(np.zeros((0, 4), np.uint8)).shape == (0, 4)
    with pytest.raises(InputError, match="expected a 2D"):
        distance_to_background(np.zeros((2, 2, 2), np.uint8))


def whole_frame_support(mask: np.ndarray, inside_cap_px: float, smooth_sigma_px: float) -> np.ndarray:
    values = np.minimum(whole_framesigned_distance(mask), np.float32(inside_cap_px))
    if smooth_sigma_px == 0.0:
        return values
    return cv2.GaussianBlur(values, (0, 0), sigmaX=smooth_sigma_px, sigmaY=smooth_sigma_px,
                            borderType=cv2.BORDER_REPLICATE)


@pytest.mark.parametrize(("size", "smooth_sigma_px"), [((480, 640), 1.0), ((301, 517), 2.0), ((240, 330), 0.0)])
def test_a_support_read_on_its_window_around_the_silhouette_equals_the_whole_frames(size, smooth_sigma_px):
    """Samples near the body are read on the window, others on the whole frame computed then; both
    give the whole frame's values to the bit (frames whose width is no multiple of the blur's
    column alignment, silhouettes cut by the frame's edges)."""
    rng = np.random.default_rng(8)
    windowed = 0
    for mask in random_silhouettes(seed=9, count=40, size=size):
        support = support_from_mask(mask, inside_cap_px=4.0, smooth_sigma_px=smooth_sigma_px)
        reference = SupportImage(whole_frame_support(mask, 4.0, smooth_sigma_px))
        rows, columns = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        reach = SILHOUETTE_MARGIN_PX  # the window's margin about the silhouette's box
        near = np.column_stack([rng.uniform(columns[0] - reach, columns[-1] + reach, 200),
                                rng.uniform(rows[0] - reach, rows[-1] + reach, 200)])
        far = np.column_stack([rng.uniform(-50, size[1] + 50, 200), rng.uniform(-50, size[0] + 50, 200)])
        for pixels in (near, far):
            sample, expected = support.sample(pixels), reference.sample(pixels)
            assert np.array_equal(sample.values, expected.values)
            assert np.array_equal(sample.gradient, expected.gradient)
            windowed += pixels is near and support._values is None
        assert np.array_equal(support.values, reference.values)
    assert windowed > 20


def test_a_windowed_support_reads_no_pixels_as_the_whole_frame_does():
    mask = np.zeros((480, 640), bool)
    mask[100:200, 300:360] = True
    windowed, whole = support_from_mask(mask), SupportImage(support_from_mask(mask).values)
    sample, expected = windowed.sample(np.zeros((0, 2))), whole.sample(np.zeros((0, 2)))
    assert sample.values.shape == (0,) and sample.gradient.shape == (0, 2)
    assert np.array_equal(sample.values, expected.values) and np.array_equal(sample.gradient, expected.gradient)


@pytest.mark.parametrize(("size", "smooth_sigma_px"), [((480, 640), 1.0), ((301, 517), 2.0)])
def test_a_window_that_also_covers_a_box_reads_it_on_the_window_with_the_whole_frames_values(size, smooth_sigma_px):
    """A partial silhouette and a box where the skeleton is expected beside it (also_around): samples
    in the box are read on the window, to the whole frame's bits; a box past the frame's edge or
    empty changes nothing but the window's size."""
    rng = np.random.default_rng(12)
    height, width = size
    checked = 0
    for mask in random_silhouettes(seed=13, count=30, size=size):
        top, left = int(rng.integers(0, height - 40)), int(rng.integers(0, width - 40))
        box = (slice(top, top + int(rng.integers(10, 120))), slice(left, left + int(rng.integers(10, 200))))
        support = support_from_mask(mask, inside_cap_px=4.0, smooth_sigma_px=smooth_sigma_px, also_around=box)
        reference = SupportImage(whole_frame_support(mask, 4.0, smooth_sigma_px))
        inside_box = np.column_stack([rng.uniform(box[1].start, min(box[1].stop, width) - 1, 300),
                                      rng.uniform(box[0].start, min(box[0].stop, height) - 1, 300)])
        sample, expected = support.sample(inside_box), reference.sample(inside_box)
        assert np.array_equal(sample.values, expected.values)
        assert np.array_equal(sample.gradient, expected.gradient)
        checked += support._values is None  # read on the window, no whole frame computed
        held, row, column = support.held_values()
        if support._values is None:  # the window holds the box grown by its margin, within the frame
            grown = TARGETS_MARGIN_PX
            assert row <= max(box[0].start - grown, 0) and column <= max(box[1].start - grown, 0)
            assert row + held.shape[0] >= min(box[0].stop + grown, height)
            assert column + held.shape[1] >= min(box[1].stop + grown, width)
        for odd in ((slice(height + 5, height + 50), slice(0, 10)), (slice(20, 20), slice(0, 0))):
            assert np.array_equal(support_from_mask(mask, 4.0, None, smooth_sigma_px, also_around=odd).values,
                                  reference.values)
    assert checked > 15


@pytest.mark.parametrize("from_parts", [False, True])
def test_a_read_outside_the_window_widens_it_around_the_read_with_the_whole_frames_values(from_parts):
    """A read outside the window (a limb straying from a partial silhouette) asks for a window
    that also covers it: computed around the read (the old window inside it), to the whole
    frame's bits, the whole frame not computed; where a wider window would be the frame, the
    frame. The same for a support rebuilt from its parts in another process."""
    from ibik_pin.vision.support_parts import support_from_parts, windowed_parts

    rng = np.random.default_rng(21)
    widened = 0
    for mask in random_silhouettes(seed=22, count=40, size=(480, 640)):
        support = support_from_mask(mask, inside_cap_px=4.0)
        if support._values is not None:  # a window as large as the frame
            continue
        if from_parts:
            support = support_from_parts(windowed_parts(support))
        reference = SupportImage(whole_frame_support(mask, 4.0, 1.0)).values
        old, old_row, old_column = support.held_values()
        row, column = int(rng.integers(0, 478)), int(rng.integers(0, 638))
        covering = (slice(row, row + 2), slice(column, column + 2))
        held, held_row, held_column = support.held_values(covering=covering)
        if support._values is not None:  # the wider window would be the frame
            assert (held_row, held_column) == (0, 0) and np.array_equal(held, reference)
            continue
        assert held_row <= row and row + 2 <= held_row + held.shape[0]
        assert held_column <= column and column + 2 <= held_column + held.shape[1]
        assert held_row <= old_row and old_row + old.shape[0] <= held_row + held.shape[0]
        assert held_column <= old_column and old_column + old.shape[1] <= held_column + held.shape[1]
        rows, columns = held.shape
        assert np.array_equal(held, reference[held_row:held_row + rows, held_column:held_column + columns])
        widened += held.size > old.size
    assert widened > 15


def test_the_overlap_term_reads_a_straying_sample_on_a_wider_window_not_the_whole_frame():
    """The image term's value and gradient with a sample outside the support's window: those of
    the whole frame's support, read on a window widened around the samples."""
    from ibik_pin.configuration import Configuration
    from ibik_pin.model import load_arm
    from ibik_pin.tasks import ImageTask
    from ibik_pin.tasks.image import View
    from ibik_pin.vision.pinhole import look_at_camera

    body = load_arm()
    configuration = Configuration(body.model)
    camera = look_at_camera("front", (640, 480), 500.0, eye=[0.0, -3.0, 0.0], target=[0.0, 0.0, 0.0],
                            up=[0.0, 0.0, 1.0])
    mask = np.zeros((480, 640), bool)
    mask[20:60, 20:60] = True  # a silhouette in a corner: the arm's samples lie outside its window
    whole = SupportImage(support_from_mask(mask, inside_cap_px=4.0).values)
    windowed = support_from_mask(mask, inside_cap_px=4.0)
    first_window = windowed.held_values()[0].shape
    on_window, on_frame = ImageTask(body, [View(camera, windowed)]), ImageTask(body, [View(camera, whole)])
    assert on_window.compute_value(configuration) == on_frame.compute_value(configuration)
    np.testing.assert_array_equal(on_window.compute_gradient(configuration), on_frame.compute_gradient(configuration))
    assert windowed._values is None  # a wider window, not the whole frame
    assert windowed.held_values()[0].size > np.prod(first_window)


# The near transform up to a 20 px reach, the separable one beyond.
@pytest.mark.parametrize("cap", [1.0, 2.5, 6.0, 13.7, 19.5, 27.0])
def test_an_inside_distance_exact_up_to_a_limit_gives_the_capped_support_of_the_whole_transform(cap):
    """The transform that looks no farther than the limit: exact values up to it,
    values beyond it where the distance is; the supports it gives, windowed and whole-frame, are the
    same to the bit."""
    from ibik_pin.vision.distance import inside_distance

    masks = list(random_silhouettes(seed=11, count=60, size=(90, 130)))
    rng = np.random.default_rng(12)
    for _ in range(20):  # speckle: runs of every length
        masks.append((rng.random((60, 80)) < rng.uniform(0.3, 0.95)).astype(np.uint8))
    for shape in ((1, 40), (40, 1), (2, 3)):  # rows and columns narrower than the reach
        masks.append((rng.random(shape) < 0.5).astype(np.uint8))
    for mask in masks:
        scanned = scan_mask(mask)
        if scanned.box is None or scanned.set_pixels == mask.size:
            continue
        exact = inside_distance(scanned.mask, scanned.box)
        limited = inside_distance(scanned.mask, scanned.box, limit=cap + 0.5)
        assert limited.limit == cap + 0.5 and exact.limit is None
        within = exact.values <= cap + 0.5
        assert np.array_equal(limited.values[within], exact.values[within])
        assert np.all(limited.values[~within] > cap + 0.5)
        expected = support_from_mask(mask, inside_cap_px=cap)
        support = support_from_mask(scanned, inside_cap_px=cap, inside=limited)
        window, row, column = support.held_values()
        whole, _, _ = expected.held_values(whole_frame=True)
        assert np.array_equal(window, whole[row:row + window.shape[0], column:column + window.shape[1]])
        assert np.array_equal(support.values, expected.values)


@pytest.mark.parametrize("limit", [0.0, -3.0, float("nan"), float("inf")])
def test_an_inside_distance_limit_must_be_a_positive_number_of_pixels(limit):
    from ibik_pin.vision.distance import inside_distance

    scanned = scan_mask(next(iter(random_silhouettes(seed=2, count=1))))
    with pytest.raises(InputError, match="limit: expected a positive number of pixels"):
        inside_distance(scanned.mask, scanned.box, limit=limit)


def test_a_limited_inside_distance_is_refused_where_more_of_it_is_read():
    from ibik_pin.vision.distance import inside_distance

    mask = next(iter(random_silhouettes(seed=2, count=5)))
    scanned = scan_mask(mask)
    limited = inside_distance(scanned.mask, scanned.box, limit=4.5)
    with pytest.raises(InputError, match=r"exact up to 4\.5 px only"):
        support_from_mask(scanned, inside_cap_px=4.5, inside=limited)
    with pytest.raises(InputError, match=r"exact up to 4\.5 px only"):
        support_from_mask(scanned, inside_cap_px=None, inside=limited)
    support_from_mask(scanned, inside_cap_px=4.0, inside=limited)  # within: accepted
    # The medial axis needs every depth: it computes its own rather than read the limited one.
    assert np.array_equal(medial_axis_pixels(mask, inside=limited), medial_axis_pixels(mask))
