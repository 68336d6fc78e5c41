"""`--trial-lengths images`: the legs' lengths chosen on the trial's silhouettes, the arms' by reach.

A first pass without the image (PIK) puts every frame's limb ends on their targets; around that
pose, subject.trial_lengths.refine_from_images tries one factor per leg on both its segments (the
criteria's overlap favours a thick thigh, so they tell a leg's length, not its split) and keeps the
one whose knees, each at its best swivel, explain the views best. Then each leg's split between
thigh and shank, its sum kept, is chosen on the silhouettes' centre lines, which do not depend on
the limbs' widths, with the knees where the first step put them (subject.split_cue.refine_split;
docs/sweep.md). The arms go by the targets' reach (on the silhouettes, even with no elbow inside
the trunk, the arms' lengths and the elbows came out worse). One view sees no depth: with fewer
than two cameras the legs too go by reach. This is what the sweep's
`--lengths images` does (experiments/sweepkit/lengths.py), inside `ibik track`.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace

import numpy as np

from ibik_pin.exceptions import IbikWarning
from ibik_pin.model import BodyModel
from ibik_pin.readahead.frame_images import FrameImages, frame_images
from ibik_pin.readahead.view_workers import built_ahead, usable_cores
from ibik_pin.subject.scaling import keypoint_lengths
from ibik_pin.subject.split_cue import refine_split
from ibik_pin.subject.trial_lengths import TrialLengths, refine_from_images, refine_from_reach
from ibik_pin.tasks.image import ImageTask
from ibik_pin.tasks.silhouette_axis import SilhouetteAxisTask
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.tracker import Tracker
from ibik_pin.tracking.views import support_caps

__all__ = ["refine_lengths_on_images"]

LEGS = ("left_leg", "right_leg")
ARMS = ("left_arm", "right_arm")
# The legs' factor is chosen on at most this many frames, spread evenly over the trial: the sweep
# that decided this refinement chose it on windows of 40 frames (docs/sweep.md), and every frame
# more costs its support images and a grid of swivel searches (120 frames of the demo, 4 views:
# about 2 s against 1.2 s for the whole solve).
MOST_FRAMES = 40


def refine_lengths_on_images(body: BodyModel, names: list[str], targets_m: np.ndarray, cameras: Sequence,
                             masks_of_frame: Callable[[int], Sequence[np.ndarray]],
                             settings: TrackingSettings) -> TrialLengths:
    """The calibrated body's limb lengths refined on this trial: legs on the silhouettes around a
    blind first pass (two views or more), arms (and legs with one view) by the targets' reach.

    Args:
        targets_m: (F, T, 3) the targets in the model's frame [m]; NaN where absent.
        masks_of_frame: frame index -> one silhouette per camera (as the tracker reads them).
        settings: the run's; the first pass drops the image, the criteria take its weights.
    """
    lengths = keypoint_lengths(body)
    if len(cameras) < 2:
        return refine_from_reach(lengths, names, targets_m)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IbikWarning)
        first_pass = Tracker(body, [], replace(settings, use_image=False)).track(names, targets_m)
    centre = np.nanmean(targets_m.reshape(-1, 3), axis=0)
    caps = support_caps(cameras, centre)
    scales = support_caps(cameras, centre, settings.axis_scale)
    image_task = ImageTask(body, samples_per_segment=settings.samples_per_segment)
    axis_task = SilhouetteAxisTask(body)

    count = first_pass.keypoints.shape[0]
    sampled = [int(frame) for frame in np.unique(np.linspace(0, count - 1, min(count, MOST_FRAMES)).round())
               if np.all(np.isfinite(first_pass.keypoints[int(frame)]))]

    def pose(frame: int) -> dict[str, np.ndarray]:
        return {name: first_pass.keypoints[frame, k] for k, name in enumerate(first_pass.keypoint_names)}

    def views(frame: int) -> FrameImages:
        return frame_images(masks_of_frame, cameras, caps, scales, frame, workers=usable_cores())

    def frames() -> Iterator:
        # The next frame's views are built while this one's grid is scored.
        built = built_ahead(views, sampled) if usable_cores() > 1 else map(views, sampled)
        for frame, images in zip(sampled, built, strict=True):
            image_task.set_views(images.views)
            axis_task.set_views(images.axis_views or [])
            yield pose(frame), [(image_task, 1.0), (axis_task, settings.axis_weight)]

    # The run's own solve reads the same targets and silhouettes next and says what is wrong with
    # them, once per cause: said here too, each frame's empty view would be said again and again.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IbikWarning)
        legs = refine_from_images(body, lengths, frames(), limbs=LEGS, keep_ratio=True)
        legs = refine_split(body, legs, [pose(frame) for frame in sampled],
                            lambda index: masks_of_frame(sampled[index]), cameras, centre, workers=usable_cores())
    arms = refine_from_reach(lengths, names, targets_m, limbs=ARMS)
    refined = dict(lengths)
    for limb_lengths in (legs, arms):
        refined.update({name: value for name, value in limb_lengths.lengths.items()
                        if value != lengths[name]})
    return TrialLengths(refined, dict(lengths), {**legs.evidence, **arms.evidence})
