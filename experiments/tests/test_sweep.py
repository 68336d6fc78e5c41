"""The sweep benchmark: its draws stay in their ranges, the static's drift is what it says, and a
quick run writes every figure."""

import json

import numpy as np
import pytest
import sweep
from realdata.runner import DEFAULT_DATA
from sweepkit.conditions import PARENTS, draw_condition, drift_static
from sweepkit.motions import MOTIONS

needs_data = pytest.mark.skipif(not DEFAULT_DATA.is_dir(), reason="the shared mocap data folder is absent")


def test_conditions_are_seeded_and_stay_in_their_ranges():
    conditions = [draw_condition(index, seed=3) for index in range(2 * len(MOTIONS))]
    assert draw_condition(5, seed=3) == conditions[5]
    assert {c.motion for c in conditions} == set(MOTIONS)
    for condition in conditions:
        first, second = condition.cameras[:2]
        separation = abs((second.azimuth_deg - first.azimuth_deg + 180.0) % 360.0 - 180.0)
        assert 45.0 - 1e-9 <= separation <= 135.0 + 1e-9
        for camera in condition.cameras:
            assert 0.5 <= camera.height_m <= 2.5 and 3.0 <= camera.distance_m <= 7.0 and 50.0 <= camera.fov_deg <= 90.0
        assert 0.7 <= condition.body.limb_radius_factor <= 1.4
        assert all(0.96 <= f <= 1.04 for f in condition.length_factors.values())
        assert 0.0 <= condition.target_noise_mm <= 10.0


def test_the_static_drift_scales_each_segment_by_its_own_factor():
    names = ["Hip", "LHip", "LKnee", "LAnkle", "Neck", "LShoulder", "LElbow", "LWrist"]
    rng = np.random.default_rng(0)
    static = rng.normal(0.0, 0.3, (3, len(names), 3))
    factors = {name: 1.0 + 0.01 * k for k, name in enumerate(names)}
    drifted = drift_static(names, static, factors)
    for child in names[1:]:
        parent = names.index(PARENTS[child])
        before = np.linalg.norm(static[:, names.index(child)] - static[:, parent], axis=1)
        after = np.linalg.norm(drifted[:, names.index(child)] - drifted[:, parent], axis=1)
        np.testing.assert_allclose(after, factors[child] * before, rtol=1e-12)
    np.testing.assert_array_equal(drifted[:, 0], static[:, 0])


@needs_data
def test_a_quick_sweep_writes_every_figure(tmp_path):
    result = sweep.main(["--quick", "--out", str(tmp_path), "--quiet"])
    written = json.loads((tmp_path / "sweep.json").read_text())
    assert len(written["conditions"]) == 2 and len(written["runs"]) == 2 * 3
    for key in ("pik/clean", "ibik2v/clean", "ibik2v/defects"):
        for group in ("elbows", "knees", "targets"):
            stats = result["summary"]["all"][key][group]
            assert stats["count"] == 2 and 0.0 < stats["median"] <= stats["p90"] < 500.0
    # Targets are met to within the drawn noise and the model's keypoint offsets.
    assert result["summary"]["all"]["pik/clean"]["targets"]["p90"] < 40.0
    assert "| IBIK 2v | clean |" in (tmp_path / "sweep.md").read_text()


@needs_data
def test_target_filters_run_paired_on_the_same_condition(tmp_path):
    result = sweep.main(["--quick", "--conditions", "1", "--silhouettes", "clean", "--target-filters", "off,auto",
                         "--out", str(tmp_path), "--quiet"])
    runs = {(run["variant"], run["target_filter"]): run for run in result["runs"]}
    assert set(runs) == {(v, f) for v in ("pik", "ibik2v") for f in ("off", "auto")}
    assert set(result["summary"]) == {"target_filter=off", "target_filter=auto"}
    # Condition 0 draws 9.3 mm of target noise: the filtered targets lie closer to the mocap joints.
    for name in ("pik", "ibik2v"):
        assert runs[(name, "auto")]["groups_mm"]["targets"] < runs[(name, "off")]["groups_mm"]["targets"] - 2.0
    table = (tmp_path / "sweep.md").read_text()
    assert "Target filters paired by condition" in table and "| IBIK 2v | clean | targets |" in table


@needs_data
def test_the_silhouette_body_widens_flattens_and_loosens_as_drawn():
    from realdata.clips import load_clip
    from sweepkit.body import BodyShape, SweepBody
    from sweepkit.conditions import place_cameras
    from sweepkit.motions import anatomy_of

    condition = draw_condition(8, seed=0)  # jumps01_01: 01_01.bvh's MotionBuilder names
    spec = MOTIONS[condition.motion]
    clip = load_clip(spec, DEFAULT_DATA, 4, 30.0)
    cameras, _ = place_cameras(clip, condition)

    def pixels(shape: BodyShape) -> int:
        body = SweepBody(clip.joint_names, spec.source, anatomy_of(clip.joint_names, spec.source),
                         clip.static_joints, shape)
        return int(body.render_frame(clip.joints[2], cameras[0])[0].sum())

    plain = pixels(BodyShape())
    assert pixels(BodyShape(limb_radius_factor=0.7)) < plain < pixels(BodyShape(limb_radius_factor=1.4))
    assert pixels(BodyShape(loose_m=0.03)) > 1.05 * plain
    flat = pixels(BodyShape(ellipticity=1.5))
    assert flat != plain and abs(flat - plain) < 0.15 * plain  # the sections' areas are kept
