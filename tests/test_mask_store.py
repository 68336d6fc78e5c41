"""CroppedMasks: a video's masks kept as bounding-box crops give back exactly what was stored."""

from __future__ import annotations

import numpy as np
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.vision.mask_store import CroppedMasks


@pytest.fixture
def masks():
    generator = np.random.default_rng(7)
    frames = [np.zeros((40, 60), bool) for _ in range(5)]
    frames[0][5:12, 50:60] = True  # touching the right edge
    frames[1][30:40, 0:3] = True  # the bottom-left corner
    frames[3] = generator.random((40, 60)) > 0.97  # scattered pixels
    frames[4][20, 20] = True  # one pixel; frame 2 stays empty
    return frames


def test_every_mask_comes_back_exactly_and_takes_less_room(masks):
    stored = CroppedMasks((60, 40), masks)
    assert len(stored) == 5
    for original, back in zip(masks, stored, strict=True):
        assert back.dtype == bool and back.shape == (40, 60)
        np.testing.assert_array_equal(back, original)
    assert stored.nbytes < sum(mask.nbytes for mask in masks)
    np.testing.assert_array_equal(stored[-1], masks[4])
    assert [mask.sum() for mask in stored[1:3]] == [masks[1].sum(), 0]


def test_assignment_replaces_a_mask_and_a_returned_mask_is_a_copy(masks):
    stored = CroppedMasks((60, 40), masks)
    stored[0] = masks[1]
    np.testing.assert_array_equal(stored[0], masks[1])
    stored[4][:] = True  # a copy: the stored mask is untouched
    np.testing.assert_array_equal(stored[4], masks[4])


def test_fitted_pads_or_cuts_at_the_right_and_bottom(masks):
    stored = CroppedMasks((60, 40), masks)
    padded, cut = stored.fitted((64, 42)), stored.fitted((55, 35))
    for original, wide, narrow in zip(masks, padded, cut, strict=True):
        expected_wide = np.zeros((42, 64), bool)
        expected_wide[:40, :60] = original
        np.testing.assert_array_equal(wide, expected_wide)
        np.testing.assert_array_equal(narrow, original[:35, :55])


def test_a_mask_of_another_size_is_refused():
    with pytest.raises(InputError, match="expected 40 x 60"):
        CroppedMasks((60, 40), [np.zeros((60, 40), bool)])


def test_crops_come_out_as_stored_and_go_in_without_the_full_frame(masks):
    stored = CroppedMasks((60, 40), masks)
    top, left, crop = stored.crop(0)
    assert (top, left, crop.shape) == (5, 50, (7, 10))
    assert stored.crop(2)[2].shape == (0, 0)  # empty
    padded = np.zeros((12, 20), bool)
    padded[3:10, 10:20] = masks[0][5:12, 50:60]  # the same silhouette with an empty margin
    built = CroppedMasks((60, 40))
    built.append_crop(2, 40, padded)
    np.testing.assert_array_equal(built[0], masks[0])
    assert built.crop(0)[:2] == (5, 50)  # cut to its own bounding box
    built.set_crop(0, 0, 0, np.zeros((4, 4), bool))
    assert not built[0].any()
    with pytest.raises(InputError, match="leaves the 40 x 60 frame"):
        built.append_crop(35, 0, np.ones((6, 2), bool))
