"""Mask files in the conventions users' tools write: alpha channel, 16-bit, label images, float."""

import cv2
import numpy as np
import pytest

from ibik_pin.exceptions import IbikError, InputError
from ibik_pin.io.masks import decode_mask, mask_convention, read_mask


@pytest.fixture
def person():
    rng = np.random.default_rng(3)
    return rng.random((30, 40)) < 0.35


def test_a_silhouette_in_the_alpha_channel_is_read_from_the_alpha_not_the_colour(tmp_path, person):
    image = np.zeros((30, 40, 4), np.uint8)  # black everywhere: the colour says "no one"
    image[..., 3] = person * 255
    cv2.imwrite(str(tmp_path / "alpha.png"), image)
    np.testing.assert_array_equal(read_mask(tmp_path / "alpha.png"), person)
    assert mask_convention(tmp_path / "alpha.png") == "alpha channel, thresholded at mid-range"


def test_an_opaque_rgba_export_is_read_from_its_colour(tmp_path, person):
    image = np.full((30, 40, 4), 255, np.uint8)
    image[..., :3] = person[..., None] * 255
    cv2.imwrite(str(tmp_path / "opaque.png"), image)
    np.testing.assert_array_equal(read_mask(tmp_path / "opaque.png"), person)
    assert mask_convention(tmp_path / "opaque.png").startswith("colour image read as grey")


@pytest.mark.parametrize(("on_value", "convention"), [(1, "16-bit label image, non-zero = person"),
                                                      (65535, "16-bit mask, thresholded at mid-range"),
                                                      (255, "16-bit label image, non-zero = person")])
def test_16_bit_masks_keep_their_person_whatever_the_value_that_marks_it(tmp_path, person, on_value, convention):
    cv2.imwrite(str(tmp_path / "m16.png"), (person * on_value).astype(np.uint16))
    np.testing.assert_array_equal(read_mask(tmp_path / "m16.png"), person)
    assert mask_convention(tmp_path / "m16.png") == convention


def test_a_label_image_of_two_people_is_refused_naming_its_labels(tmp_path, person):
    labels = person.astype(np.uint8)
    labels[:, 20:][person[:, 20:]] = 2
    cv2.imwrite(str(tmp_path / "labels.png"), labels)
    with pytest.raises(InputError, match=r"labels\.png': expected a mask of one person .* 2 labels \(1, 2\)"):
        read_mask(tmp_path / "labels.png")


def test_a_float_mask_is_thresholded_at_one_half(person):
    soft = np.where(person, 0.8, 0.2).astype(np.float32)
    mask, convention = decode_mask(soft)
    np.testing.assert_array_equal(mask, person)
    assert convention == "float image, thresholded at 0.5"


def test_a_jpeg_compressed_mask_still_thresholds_at_mid_grey(tmp_path):
    person = np.zeros((60, 80), bool)
    person[15:45, 20:60] = True
    cv2.imwrite(str(tmp_path / "m.jpg"), person.astype(np.uint8) * 255, [cv2.IMWRITE_JPEG_QUALITY, 60])
    assert (read_mask(tmp_path / "m.jpg") != person).mean() < 0.01


@pytest.mark.parametrize("size", ["640x480", (640,), (640.0, 480), (0, 480), (True, 480), 640])
def test_an_expected_size_that_is_not_two_positive_whole_numbers_is_an_input_error(tmp_path, size):
    cv2.imwrite(str(tmp_path / "m.png"), np.zeros((30, 40), np.uint8))
    with pytest.raises(IbikError, match=r"expected_size: expected \(width, height\) as two positive whole"):
        read_mask(tmp_path / "m.png", size)


def test_an_array_that_is_no_image_is_refused_by_shape_and_type():
    with pytest.raises(InputError, match=r"found an array of shape \(2, 3, 7\)"):
        decode_mask(np.zeros((2, 3, 7), np.uint8))
    with pytest.raises(InputError, match="found int64"):
        decode_mask(np.zeros((2, 3), np.int64))
