"""Section 4 acceptance: IBIK against PIK on fixed clips of real walking and real boxing.

The paper's Table 1 setting: the leg (hip and knee) on walking with the ankle as end effector, the
arm (shoulder and elbow) on boxing with the wrist as end effector, the chain's base on the true
joint, whole-body silhouettes rendered into HumanEva-like cameras. Clean silhouettes, 2 views, the
default scheme (the hierarchical QP).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from paper.section4 import (
    DEFECT_MASK_FILTER_RADIUS,
    DEFECT_TARGET_NOISE_MM,
    DEFECTS,
    load_motion,
    prepare_clip,
    render_views,
    run_chain,
    run_full_body,
    subset_views,
    temporally_filtered,
)

from ibik_pin.exceptions import IbikWarning
from tests.paths import TEST_DATA

DATA = TEST_DATA


@pytest.fixture(scope="module")
def walking():
    motion = load_motion(DATA / "35_01_excerpt.amc", "asf", DATA / "35.asf")
    return prepare_clip("cmu35_01", motion, "asf", slice(0, 60, 2))


@pytest.fixture(scope="module")
def boxing():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IbikWarning)
        motion = load_motion(DATA / "Boxing_Toes_300-419.bvh", "boxing")
    return prepare_clip("boxing", motion, "boxing", slice(0, 120, 2))


@pytest.mark.parametrize(("chain", "clip_name"), [("leg", "walking"), ("arm", "boxing")])
def test_ibik_with_two_views_halves_pik_error_and_stays_under_25_mm(chain, clip_name, request):
    clip = request.getfixturevalue(clip_name)
    views = subset_views(render_views(clip, 4, seed=1), 2)
    pik = run_chain(chain, clip, None, "pik")
    ibik = run_chain(chain, clip, views, "ibik", scheme="qp")
    assert ibik.mean_error_mm <= 0.5 * pik.mean_error_mm
    assert ibik.mean_error_mm <= 25.0


@pytest.mark.parametrize(("chain", "clip_name"), [("leg", "walking"), ("arm", "boxing")])
def test_ibik_with_two_views_still_halves_pik_error_with_defective_silhouettes(chain, clip_name, request):
    """Erosion, dilation, holes, blobs, lost limbs (seeded) and 5 mm target noise for both."""
    clip = request.getfixturevalue(clip_name)
    rig = temporally_filtered(render_views(clip, 4, defects=DEFECTS, seed=1), DEFECT_MASK_FILTER_RADIUS)
    pik = run_chain(chain, clip, None, "pik", target_noise_mm=DEFECT_TARGET_NOISE_MM, seed=2)
    ibik = run_chain(chain, clip, subset_views(rig, 2), "ibik", scheme="qp",
                     target_noise_mm=DEFECT_TARGET_NOISE_MM, seed=2)
    assert ibik.mean_error_mm <= 0.5 * pik.mean_error_mm


def test_the_posed_truth_fits_the_recorded_keypoints_within_a_centimetre(walking, boxing):
    assert np.mean(walking.fit_residual) < 0.01
    assert np.mean(boxing.fit_residual) < 0.01


def test_the_whole_body_knee_error_falls_with_the_image_on_walking(walking):
    views = subset_views(render_views(walking, 4, seed=1), 2)
    pik = run_full_body(walking, None, "pik")
    ibik = run_full_body(walking, views, "ibik", scheme="qp")
    knees = [pik.joints.index("LKnee"), pik.joints.index("RKnee")]
    assert np.mean(ibik.errors[:, knees]) < np.mean(pik.errors[:, knees])
