"""Limb lengths for a condition's runs: the static's, refined on the trial (ibik_pin.subject.
trial_lengths), or the trial's true ones (a diagnostic). A refinement is written as another static
file whose limb segments have the refined lengths (each segment scaled about its parent keypoint,
the keypoints below it carried along), which ``ibik track --static`` then calibrates on.

- "reach": every limb lengthened where its targets' 98th-percentile reach exceeds its segments' sum.
- "images": the legs' lengths (one factor for both segments, as the criteria read the silhouettes)
  chosen on the views' silhouettes around the PIK pose, pairs that cannot reach the targets
  excluded, then each leg's split between thigh and shank (its sum kept) on the silhouettes' centre
  lines, which do not depend on the limbs' widths (subject.split_cue); the arms by reach
  (the criteria put hanging arms against the trunk). One view sees no depth: there the legs too go
  by reach (on the sweep, one view's silhouettes took IBIK 1v knees from 34.0 to 36.2 mm).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from realdata.clips import STATIC_SPACING_S

from ibik_pin.human import load_human
from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import TrcData, read_trc, write_trc
from ibik_pin.readahead.frame_images import frame_images
from ibik_pin.subject.calibration import calibrate_static_trial
from ibik_pin.subject.scaling import keypoint_lengths, segment_lengths_from_keypoints
from ibik_pin.subject.split_cue import refine_split
from ibik_pin.subject.trial_lengths import DEFAULT_FACTORS, refine_from_images, refine_from_reach
from ibik_pin.tasks.image import ImageTask
from ibik_pin.tasks.silhouette_axis import SilhouetteAxisTask
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.target_filter import filter_targets
from ibik_pin.tracking.trunk import TRUNK_SECTION
from ibik_pin.tracking.views import support_caps
from ibik_pin.vision.camera import cameras_in_frame
from sweepkit.conditions import ConditionInputs, _trc, drift_static

# scaling's length names -> the static keypoint at the segment's far end (drift_static's child).
SEGMENT_CHILDREN = {"left_thigh": "LKnee", "left_shank": "LAnkle", "right_thigh": "RKnee", "right_shank": "RAnkle",
                    "left_upper_arm": "LElbow", "left_forearm": "LWrist", "right_upper_arm": "RElbow",
                    "right_forearm": "RWrist"}
LENGTHS = ("static", "reach", "images", "oracle")
#: The factors tried on both segments of a leg at once (trial_lengths' default grid).
LEG_FACTORS = DEFAULT_FACTORS


def write_static(inputs: ConditionInputs, lengths: dict[str, float], wanted: dict[str, float], name: str) -> Path:
    """The condition's static with each limb segment scaled from its `lengths` [m] (the static's own)
    to the `wanted` ones, written beside its files as static_<name>.trc."""
    static = read_trc(inputs.static).in_metres()
    factors = {SEGMENT_CHILDREN[segment]: wanted[segment] / lengths[segment] for segment in SEGMENT_CHILDREN
               if segment in lengths and segment in wanted}
    path = inputs.folder / f"static_{name}.trc"
    write_trc(path, _trc(static.marker_names, drift_static(static.marker_names, static.positions, factors),
                         1.0 / STATIC_SPACING_S))
    return path


def _report(before: dict[str, float], after: dict[str, float]) -> dict:
    return {name: {"static_mm": 1e3 * before[name], "trial_mm": 1e3 * after[name],
                   "change_mm": 1e3 * (after[name] - before[name])} for name in SEGMENT_CHILDREN if name in before}


def static_lengths(inputs: ConditionInputs) -> dict[str, float]:
    static = read_trc(inputs.static).in_metres()
    return segment_lengths_from_keypoints(static.marker_names, static.positions)


def trial_targets(inputs: ConditionInputs, target_filter: str | float = "off") -> TrcData:
    """The condition's targets [m], low-passed as ``ibik track --target-filter`` does before it reads them."""
    targets = read_trc(inputs.targets()).in_metres()
    filtered = filter_targets(targets.marker_names, targets.positions, targets.data_rate, target_filter)
    targets.positions = filtered.positions
    return targets


def reach_static(inputs: ConditionInputs, smoothing_frames: int = 3,
                 target_filter: str | float = "off") -> tuple[Path, dict]:
    """The static with every limb lengthened as far as the trial's targets (filtered so) need."""
    lengths = static_lengths(inputs)
    targets = trial_targets(inputs, target_filter)
    refined = refine_from_reach(lengths, targets.marker_names, targets.positions, smoothing_frames=smoothing_frames)
    name = "reach" if target_filter == "off" else f"reach_{target_filter}"
    return write_static(inputs, lengths, refined.lengths, name), _report(lengths, refined.lengths)


def oracle_static(inputs: ConditionInputs) -> tuple[Path, dict]:
    """The static with the trial's true limb lengths (a diagnostic: what lengths are worth)."""
    lengths = static_lengths(inputs)
    wanted = segment_lengths_from_keypoints(inputs.truth_names, inputs.truth)
    return write_static(inputs, lengths, wanted, "oracle"), _report(lengths, wanted)


def image_static(inputs: ConditionInputs, estimate: TrcData, views: int, silhouettes: str,
                 settings: TrackingSettings | None = None, smoothing_frames: int = 3,
                 factors: np.ndarray = LEG_FACTORS, target_filter: str | float = "off",
                 split: bool = True, arms: str = "reach") -> tuple[Path, dict]:
    """The static with the legs' lengths the first `views` cameras' silhouettes prefer around the
    pose `estimate` (a PIK run's joints.trc), the arms' by reach: each leg's factor, then (`split`)
    its split between thigh and shank on the centre lines (subject.split_cue.refine_split).

    `arms="images"` (a trial, not kept: docs/sweep.md) chooses the arms' factor on the silhouettes
    like the legs', no elbow inside the trunk."""
    if views < 2:
        path, report = reach_static(inputs, smoothing_frames, target_filter)
        return path, dict(report, evidence="one view: the reach only")
    settings = settings or TrackingSettings()
    body = calibrate_static_trial(inputs.static, load_human()).body
    model_lengths = keypoint_lengths(body)
    cameras = cameras_in_frame(read_calibration(inputs.calibration), POSE2SIM_TRC_TO_WORLD)[:views]
    targets = trial_targets(inputs, target_filter)
    centre = np.nanmean(targets.positions[:, targets.marker_names.index("Hip")], axis=0)
    caps = support_caps(cameras, centre)
    scales = support_caps(cameras, centre, settings.axis_scale)
    folder = inputs.masks(silhouettes)

    def source(frame: int) -> list[np.ndarray]:
        return [cv2.imread(str(folder / camera.name / f"{frame:06d}.png"), cv2.IMREAD_GRAYSCALE) > 127
                for camera in cameras]

    image_task = ImageTask(body, samples_per_segment=settings.samples_per_segment)
    axis_task = SilhouetteAxisTask(body)

    def frames():
        for frame in range(estimate.positions.shape[0]):
            images = frame_images(source, cameras, caps, scales, frame)
            image_task.set_views(images.views)
            axis_task.set_views(images.axis_views)
            keypoints = {name: estimate.positions[frame, k] for k, name in enumerate(estimate.marker_names)}
            yield keypoints, [(image_task, 1.0), (axis_task, settings.axis_weight)]

    on_images = ("left_leg", "right_leg") + (("left_arm", "right_arm") if arms == "images" else ())
    legs = refine_from_images(body, model_lengths, frames(), factors=factors, limbs=on_images, keep_ratio=True,
                              trunk_section=TRUNK_SECTION)
    if split:
        poses = [{name: estimate.positions[frame, k] for k, name in enumerate(estimate.marker_names)}
                 for frame in range(estimate.positions.shape[0])]
        legs = refine_split(body, legs, poses, source, cameras, centre)
    by_reach = refine_from_reach(model_lengths, targets.marker_names, targets.positions,
                                 limbs=("left_arm", "right_arm"), smoothing_frames=smoothing_frames)
    lengths = static_lengths(inputs)
    wanted = dict(lengths)
    for name in SEGMENT_CHILDREN:
        on_silhouettes = "thigh" in name or "shank" in name or arms == "images"
        refined = legs.lengths[name] if on_silhouettes else by_reach.lengths[name]
        wanted[name] = lengths[name] * refined / model_lengths[name]
    report = dict(_report(lengths, wanted), evidence=legs.evidence)
    suffix = "" if target_filter == "off" else f"_{target_filter}"
    return write_static(inputs, lengths, wanted, f"images{views}v_{silhouettes}{suffix}"), report
