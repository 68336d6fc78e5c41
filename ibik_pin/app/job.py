"""The job of `ibik track`: what it was asked to do, as a plain record the application reads.

The job is checked when made (what the CLI refuses, the API refuses too) and never rewritten:
what the application computes from it (targets triangulated from the videos, the stack as solved)
is returned by the functions that compute it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ibik_pin.app.axes import TRC_AXES
from ibik_pin.app.options import as_options
from ibik_pin.app.video_people import parse_person
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.solvers import available_qp_solvers, qp_solver_available
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.target_filter import parse_target_filter

# Where the silhouettes of --videos come from (app.video_inputs.resolve_segmenter).
SEGMENTERS = ("auto", "mediapipe", "mog2")
# How the limb lengths are refined on the trial itself (subject.trial_lengths): not, by the targets' reach,
# or the legs on the silhouettes (app.trial_lengths_images).
TRIAL_LENGTHS = ("off", "reach", "images")
# Bounds that keep a run finite: at 1000 steps a frame already takes seconds, and a majority vote
# over more than 61 frames (a second at 60 Hz) is no longer a filter of flicker.
MAX_ITERATIONS = 1000
MAX_MASK_FILTER_RADIUS = 30


def check_run_bounds(settings: TrackingSettings) -> None:
    """Refuse step counts and a mask filter outside the bounds above (InputError naming the option)."""
    for option, value, low, high in (("--iterations", settings.iterations, 1, MAX_ITERATIONS),
                                     ("--mask-filter", settings.mask_filter_radius, 0, MAX_MASK_FILTER_RADIUS)):
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise InputError(f"{option}: expected a whole number from {low} to {high}, found {value!r}")
    if not qp_solver_available(settings.qp_solver):
        raise UnknownNameError(f"--qp-solver: expected one of {', '.join(available_qp_solvers())} (the ones "
                               f"installed here), found {settings.qp_solver!r}")
    tolerance = settings.step_tolerance
    if tolerance is not None and not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"--step-tolerance: expected a positive number of radians, found {tolerance!r}")


@dataclass(frozen=True)
class TrackJob:
    """Everything `ibik track` was asked to do (paths as given on the command line): a record that
    the modules of the application read and never rewrite.

    `trc_axes` is the TRC files' axis convention: "auto" (detected against the calibration's
    cameras; y-up without a calibration; a C3D file's own declaration, POINT:Y_SCREEN, where it has
    one), "y-up" (Pose2Sim, OpenSim) or "z-up" (the calibration's own world); see app.axes.
    `person` is whom to follow in the videos: "auto" (app.video_people.PERSON_RULE), a person's
    number in that rule's ranking (1 the first), or "all" (each into OUT/person_N).
    `trial_lengths` "reach" lengthens a limb whose calibrated segments cannot reach its targets'
    distance on the trial (subject.trial_lengths.refine_from_reach); "images" chooses each leg's
    length on the silhouettes of two views or more, the arms' by reach (app.trial_lengths_images);
    "off" keeps the calibration's.
    `target_filter` low-passes each target keypoint over time before anything reads it
    (tracking.target_filter): "auto" (default) at the cutoff the trial's own residual analysis
    gives each keypoint, a number at that cutoff [Hz], "off" not at all.
    `targets` and `static` may be C3D files (recognised by content), their markers mapped to
    keypoints by `c3d_mapping` (a TOML mapping file; None: io.c3d's default mapping).
    """

    targets: Path | None
    out: Path
    static: Path | None = None
    calibration: Path | None = None
    masks: Path | None = None
    videos: Path | None = None
    background: Path | None = None
    cameras: list[str] | None = None
    model: Path | None = None
    settings: TrackingSettings = field(default_factory=TrackingSettings)
    overlay: bool = False
    quiet: bool = False
    trc_axes: str = "auto"
    segmenter: str = "auto"
    triangulated_limbs: bool = False
    refit_cameras: list[str] | None = None
    c3d_mapping: Path | None = None
    trial_lengths: str = "images"
    person: str | int = "auto"
    target_filter: str | float = "auto"

    def __post_init__(self) -> None:
        """Paths given as str become Paths; what the CLI refuses, the API refuses too (InputError)."""
        for name in ("targets", "out", "static", "calibration", "masks", "videos", "background", "model",
                     "c3d_mapping"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, Path):
                if isinstance(value, str) and not value.strip():
                    raise InputError(f"--{name} {value!r}: expected a path, found an empty name")
                if not isinstance(value, (str, os.PathLike)):
                    raise InputError(f"TrackJob.{name}: expected a path (str or Path), found {type(value).__name__}")
                object.__setattr__(self, name, Path(value))  # frozen: converted once, here
        if not isinstance(self.settings, TrackingSettings):
            raise InputError(f"TrackJob.settings: expected a TrackingSettings (ibik_pin.tracking.settings), found "
                             f"{type(self.settings).__name__}; e.g. TrackingSettings(iterations=3)")
        for name in ("cameras", "refit_cameras"):
            names = getattr(self, name)
            if names is not None and (isinstance(names, str) or not isinstance(names, (list, tuple))
                                      or not all(isinstance(item, str) for item in names)):
                raise InputError(f"TrackJob.{name}: expected a list of camera names, found {names!r}")
        for name in ("overlay", "quiet", "triangulated_limbs"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"TrackJob.{name}: expected True or False, found {getattr(self, name)!r}")
        for name in ("trc_axes", "segmenter", "trial_lengths"):
            if not isinstance(getattr(self, name), str):
                raise InputError(f"TrackJob.{name}: expected a name (str), found {getattr(self, name)!r}")
        object.__setattr__(self, "person", parse_person(self.person))
        with as_options({"target_filter": "--target-filter"}):
            object.__setattr__(self, "target_filter", parse_target_filter(self.target_filter))
        if self.person != "auto" and self.videos is None:
            raise InputError("--person goes with --videos (the people are found in the videos)")
        if self.masks is not None and self.videos is not None:
            raise InputError("--masks and --videos: give one source of silhouettes, not both")
        if self.background is not None and self.videos is None:
            raise InputError("--background goes with --videos")
        if self.targets is None and (self.videos is None or self.calibration is None):
            raise InputError("--targets: needed unless --videos and --calibration are given (then the end "
                             "effectors are triangulated from the videos)")
        if self.triangulated_limbs and self.targets is not None:
            raise InputError("--triangulated-limbs goes with --videos without --targets")
        if self.triangulated_limbs and self.settings.stack is not None:
            raise InputError("--triangulated-limbs and --stack: give the elbows and knees a level in your "
                             "stack instead")
        if self.trial_lengths not in TRIAL_LENGTHS:
            raise InputError(f"--trial-lengths: expected one of {', '.join(TRIAL_LENGTHS)}, "
                             f"found {self.trial_lengths!r}")
        if self.segmenter not in SEGMENTERS:
            raise InputError(f"--segmenter: expected one of {', '.join(SEGMENTERS)}, found {self.segmenter!r}")
        if self.trc_axes not in ("auto", *TRC_AXES):
            raise InputError(f"--trc-axes: expected auto, {', '.join(TRC_AXES)}, found {self.trc_axes!r}")
        check_run_bounds(self.settings)

    @property
    def inputs(self) -> list[Path | None]:
        """Every input path of the job (None for those not given)."""
        return [self.targets, self.static, self.calibration, self.masks, self.videos, self.background, self.model,
                self.c3d_mapping]
