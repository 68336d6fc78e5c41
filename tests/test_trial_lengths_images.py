"""`ibik track --trial-lengths images`: the legs' lengths chosen on the silhouettes inside a run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ibik_pin.app.demo import prepare_demo_inputs
from ibik_pin.cli import main
from ibik_pin.io.trc import METRES_PER_UNIT, read_trc, write_trc


@pytest.fixture(scope="module")
def short_legged(tmp_path_factory):
    """30 frames of real walking (CMU 35_01 at 15 Hz), 2 views; a static whose shanks are 6 % short."""
    folder = tmp_path_factory.mktemp("short_legs")
    paths = prepare_demo_inputs(folder / "input", views=2, frame_step=8)
    static = read_trc(paths.folder / "static.trc")
    for side in "LR":
        knee, ankle = static.marker_names.index(f"{side}Knee"), static.marker_names.index(f"{side}Ankle")
        below = [static.marker_names.index(n) for n in (f"{side}Ankle", f"{side}BigToe", f"{side}SmallToe",
                                                         f"{side}Heel") if n in static.marker_names]
        shift = -0.06 * (static.positions[:, ankle] - static.positions[:, knee])
        static.positions[:, below] += shift[:, None, :]  # the foot carried with the ankle
    write_trc(folder / "static_short.trc", static)
    return paths, folder / "static_short.trc"


def leg_sums_mm(segments: dict, key: str) -> dict[str, float]:
    return {limb: segments[f"{limb}_thigh"][key] + segments[f"{limb}_shank"][key] for limb in ("left", "right")}


def test_images_lengthen_short_legs_towards_the_truth_and_say_why(short_legged, tmp_path):
    paths, static = short_legged
    arguments = ["track", "--targets", str(paths.targets), "--calibration", str(paths.calibration),
                 "--masks", str(paths.masks), "--static", str(static), "--trial-lengths", "images",
                 "--quiet", "--out", str(tmp_path / "out")]
    assert main(arguments) == 0
    lengths = json.loads((tmp_path / "out" / "report.json").read_text())["trial_lengths"]
    truth = read_trc(paths.truth)
    position = dict(zip(truth.marker_names, np.transpose(truth.positions * METRES_PER_UNIT[truth.units] * 1e3,
                                                         (1, 0, 2)), strict=True))
    static_sums = leg_sums_mm(lengths["segments_mm"], "static")
    trial_sums = leg_sums_mm(lengths["segments_mm"], "trial")
    for side, limb in (("L", "left"), ("R", "right")):
        true_sum = np.median(np.linalg.norm(position[f"{side}Hip"] - position[f"{side}Knee"], axis=1)
                             + np.linalg.norm(position[f"{side}Knee"] - position[f"{side}Ankle"], axis=1))
        assert lengths["evidence"][f"{limb}_leg"]["kind"] == "images"
        # The static's legs are about 25 mm short; the refined ones lie closer to the truth.
        assert abs(trial_sums[limb] - true_sum) < abs(static_sums[limb] - true_sum) - 5.0, (
            limb, static_sums[limb], trial_sums[limb], true_sum)


def test_images_without_silhouettes_fall_back_to_the_reach(short_legged, tmp_path):
    paths, static = short_legged
    arguments = ["track", "--targets", str(paths.targets), "--static", str(static), "--no-image",
                 "--trial-lengths", "images", "--quiet", "--out", str(tmp_path / "out")]
    assert main(arguments) == 0
    evidence = json.loads((tmp_path / "out" / "report.json").read_text())["trial_lengths"]["evidence"]
    assert all(entry["kind"] == "reach" for entry in evidence.values())


def test_images_move_a_wrong_split_of_the_legs_toward_the_truth(tmp_path):
    """A static whose knees sit 4 % of the thigh too high (thighs short, shanks long, sums nearly
    kept): the centre lines move each leg's split toward the truth (the grid allows 3 %)."""
    paths = prepare_demo_inputs(tmp_path / "input", views=2, frame_step=8)
    static = read_trc(paths.folder / "static.trc")
    for side in "LR":
        hip, knee = static.marker_names.index(f"{side}Hip"), static.marker_names.index(f"{side}Knee")
        static.positions[:, knee] -= 0.04 * (static.positions[:, knee] - static.positions[:, hip])
    write_trc(tmp_path / "static_split.trc", static)
    arguments = ["track", "--targets", str(paths.targets), "--calibration", str(paths.calibration),
                 "--masks", str(paths.masks), "--static", str(tmp_path / "static_split.trc"),
                 "--trial-lengths", "images", "--quiet", "--out", str(tmp_path / "out")]
    assert main(arguments) == 0
    lengths = json.loads((tmp_path / "out" / "report.json").read_text())["trial_lengths"]
    truth = read_trc(paths.truth)
    position = dict(zip(truth.marker_names, np.transpose(truth.positions * METRES_PER_UNIT[truth.units] * 1e3,
                                                         (1, 0, 2)), strict=True))
    for side, limb in (("L", "left"), ("R", "right")):
        true_thigh = np.median(np.linalg.norm(position[f"{side}Hip"] - position[f"{side}Knee"], axis=1))
        segment = lengths["segments_mm"][f"{limb}_thigh"]
        assert lengths["evidence"][f"{limb}_leg"]["split"]["kind"] == "centre lines"
        assert abs(segment["trial"] - true_thigh) < abs(segment["static"] - true_thigh) - 4.0, (
            limb, segment, true_thigh)
