"""The real-mocap benchmark (experiments/real_mocap.py) on the excerpts in tests/data.

Walking: CMU 35_01's first 0.5 s; boxing: Boxing_Toes.bvh rows 300-419 (guard and punches). Both
at 60 Hz, 30 frames, 2 views, clean silhouettes of the mocap body (not of the tracking model).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from realdata.body import MocapBody
from realdata.clips import ClipSpec, load_clip
from realdata.inputs import _ordered_rig, prepare_inputs
from realdata.runner import run_variant, variant

from tests.paths import TEST_DATA

FRAMES = 30
MIN_REDUCTION = 0.40  # IBIK's elbow (boxing) or knee (walking) error at least 40% below PIK's
MAX_IBIK_ERROR_MM = 25.0  # ... and at most this (the acceptance bound)
# A standing adult's frontal silhouette is about 0.5-0.6 m^2 (at the reference stature); no view
# of the body may cover more than this many square metres at the subject's distance.
MAX_SILHOUETTE_AREA_M2 = 0.8
JOINT_TOLERANCE_PX = 1  # a joint at the tip of a thin capsule may fall one pixel off by rounding

WALKING = ClipSpec("walking_excerpt", "walking", "35_01_excerpt.amc", "asf", 0.0, asf="35.asf")
BOXING = ClipSpec("boxing_excerpt", "boxing", "Boxing_Toes_300-419.bvh", "boxing", 0.0)
CLIPS = {"walking": WALKING, "boxing": BOXING}


@pytest.mark.parametrize("kind", ["walking", "boxing"])
def test_mocap_body_silhouette_holds_every_projected_joint_and_stays_body_sized(kind):
    clip = load_clip(CLIPS[kind], TEST_DATA, FRAMES)
    body = MocapBody.for_subject(clip.joint_names, clip.spec.source, clip.static_joints)
    cameras = _ordered_rig(clip)
    for frame in (0, FRAMES // 2, FRAMES - 1):
        joints = clip.joints[frame]
        for camera in cameras:
            mask, limbs = body.render_frame(joints, camera)
            grown = cv2.dilate(mask.astype(np.uint8), np.ones((2 * JOINT_TOLERANCE_PX + 1,) * 2, np.uint8))
            pixels = np.rint(camera.project(joints)).astype(int)
            assert camera.contains(pixels).all()
            outside = [name for name, (u, v) in zip(clip.joint_names, pixels, strict=True) if not grown[v, u]]
            assert outside == [], f"{camera.name}, frame {frame}: joints outside the silhouette"
            depth = float(camera.points_camera(joints.mean(axis=0)[None])[0, 2])
            square_metres = mask.sum() * (depth / camera.focal_px) ** 2
            assert 0.1 * body.scale**2 < square_metres < MAX_SILHOUETTE_AREA_M2 * body.scale**2
            assert all(limb.sum() <= mask.sum() and not (limb & ~mask).any() for limb in limbs)


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    cache = tmp_path_factory.mktemp("real_mocap_cache")
    runs = {}
    for kind, spec in CLIPS.items():
        inputs = prepare_inputs(spec, TEST_DATA, FRAMES, cache)
        for name in ("pik", "ibik2v"):
            runs[kind, name] = run_variant(inputs, variant(name), "clean")
    return runs


def test_ibik_with_two_views_cuts_pik_boxing_elbow_error_by_40_percent_and_stays_under_25_mm(results):
    pik, ibik = results["boxing", "pik"].judged_mm, results["boxing", "ibik2v"].judged_mm
    assert ibik <= (1.0 - MIN_REDUCTION) * pik, f"IBIK {ibik:.1f} mm, PIK {pik:.1f} mm"
    assert ibik <= MAX_IBIK_ERROR_MM, f"IBIK {ibik:.1f} mm"


@pytest.mark.parametrize("kind", ["walking", "boxing"])
def test_the_image_does_not_pull_the_targets_off(kind, results):
    """Every target keypoint stays, on average, within 3 mm of where the blind solve puts it: the
    image moves the limbs, not the trunk (with the trunk free, the boxing Neck ended 57 mm off
    against 20 mm without the image, on the 2-s window this excerpt comes from), and not the feet
    (without the tracker's closing targets-only step, the walking toes ended 11 mm further off)."""
    pik, ibik = results[kind, "pik"].residuals_mm, results[kind, "ibik2v"].residuals_mm
    worse = {name: round(ibik[name] - pik[name], 1) for name in pik if ibik[name] > pik[name] + 3.0}
    assert worse == {}, f"residual increase over PIK [mm]: {worse}"


def test_ibik_with_two_views_keeps_the_walking_knees_under_25_mm_and_no_worse_than_pik(results):
    # On this first half second of walking the blind solve already puts the knees about 8 mm from
    # the truth, so a 40% cut (5 mm) is not asked of this excerpt; the acceptance's cut is judged on
    # the whole benchmark (experiments/real_mocap.py), whose knees PIK leaves 17-20 mm off.
    pik, ibik = results["walking", "pik"].judged_mm, results["walking", "ibik2v"].judged_mm
    assert ibik <= pik + 1.0, f"IBIK {ibik:.1f} mm, PIK {pik:.1f} mm"
    assert ibik <= MAX_IBIK_ERROR_MM and pik <= MAX_IBIK_ERROR_MM, f"IBIK {ibik:.1f} mm, PIK {pik:.1f} mm"
