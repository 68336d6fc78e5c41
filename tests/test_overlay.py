"""Overlay lines scale with the image: readable on a 1088 x 1920 portrait video, thin at 640 x 480."""

import numpy as np
import pytest

from ibik_pin.viz.overlay import _overlay_frame, skeleton_thickness


@pytest.mark.parametrize(("size_hw", "expected"), [((480, 640), 2), ((1920, 1088), 5), ((1080, 1920), 4),
                                                   ((120, 160), 2)])
def test_the_skeleton_line_width_grows_with_the_shorter_side(size_hw, expected):
    assert skeleton_thickness(size_hw) == expected


def test_a_portrait_frame_draws_a_skeleton_line_as_wide_as_its_thickness():
    mask = np.zeros((1920, 1088), bool)
    horizontal = (np.array([[100.0, 960.0]]), np.array([[900.0, 960.0]]))
    image = _overlay_frame(0, {"masks": mask, "skeletons": horizontal}, (0, 255, 0), (0, 0, 255))
    column = image[:, 500, 1]
    drawn = np.flatnonzero(column > 128)
    assert drawn.size >= skeleton_thickness((1920, 1088)) - 1 and np.ptp(drawn) <= 8
