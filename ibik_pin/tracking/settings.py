"""How the tracker solves each frame (tracking.tracker.Tracker): TrackingSettings, the choices it
offers, and their defaults."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.readahead.frames_ahead import READ_AHEAD_MODES
from ibik_pin.solvers import DEFAULT_QP_SOLVER
from ibik_pin.tracking.stack import CRITERIA, Stack
from ibik_pin.tracking.swivel_smoothing import SWIVEL_CUTOFF_HZ

__all__ = ["IMAGE_MOVES", "IMAGE_STOPS", "TrackingSettings", "check_settings"]

# Which coordinates a frame's image steps move (TrackingSettings.image_moves).
IMAGE_MOVES = ("limbs", "all")
# Where a frame's image steps end (TrackingSettings.image_stop).
IMAGE_STOPS = ("peak", "count")


@dataclass
class TrackingSettings:
    """How each frame is solved.

    Attributes:
        method: solver scheme: "qp" (default), "stack", "liegeois" or "ik".
        qp_solver: the backend of the "qp" scheme's level QPs: "active_set" (default), "proxsuite",
            or a solver qpsolvers has installed ("daqp", "proxqp", ...):
            ibik_pin.solvers.available_qp_solvers() lists them. A stack file's `qp_solver` key
            overrides it.
        iterations: solver steps per frame (the paper: 15).
        first_frame_iterations: steps for the first frame, which starts from the neutral pose:
            that many blind (no image) then that many with every level.
        first_frame_starts: starts of the first frame (see solve_first_frame). One by default:
            on the whole body, random starts of every joint at once found higher-overlap but wrong
            poses (boxing: elbows and knees 122 mm off against 44 mm from the neutral pose); the
            6-DOF chains of experiments/paper_tables.py use 8.
        use_image: False gives the blind baseline (PIK with "qp"/"stack", IK with "ik").
        samples_per_segment: n of eq. (5).
        image_step: largest image step per iteration [rad].
        posture_weight: weight of the posture prior (lowest level).
        mask_filter_radius: with r > 0, each silhouette pixel is the majority over the 2r + 1
            frames around it (images.TemporalMajority), removing one-frame segmentation flicker.
        criterion: "two-way" (default): the overlap of eq. (5)-(6) plus
            `axis_weight` times the silhouette-axis term (tasks.silhouette_axis), which asks the
            skeleton to explain the silhouette's medial axis as well; "paper": the overlap alone.
        axis_weight: weight of the silhouette-axis term in the two-way criterion.
        axis_scale: the axis term's robust scale [m] at the subject's distance: an axis sample
            farther than about this from every projected segment stops pulling.
        swivel_search: once each frame's targets are met, sample the swivel circle of every free
            elbow and knee on the image criterion and hold each at a clearly better sample, below
            the targets, for the frame's image steps (tracking.swivel): recovers limbs that fast
            motion threw into another basin of the criterion. Runs only when two views cross.
            With the trunk held (image_moves) it brought the real-mocap benchmark's boxing elbows
            from about 100 mm to under 20 mm (2 views; docs/results.md).
        swivel_cadence: a free elbow or knee whose searches keep hinting nothing is searched every
            this many frames (staggered across the limbs); one hinted lately, just freed, bent
            past the search's min_radius, or with the trunk turned more than 2.5 deg since its last
            search, is searched every frame (tracking.search_cadence). 1: every free limb every
            frame.
        swivel_refine: points the swivel search then tries on each side of a limb's best sample,
            within one sample's spacing (tracking.swivel.SwivelSearch.refine; 0: none).
        feet_by_ankle: toe and heel targets move only the joints that do not move their ankle
            (ibik_pin.feet.foot_point_joints); False lets them move the whole leg, as a plain
            end-effector target does.
        image_moves: "limbs" (default): each frame first takes `target_iterations` steps on the
            targets alone, then holds the root, spine, clavicles and neck where those left them
            (BodyModel.limb_coordinates) for the steps with the image, so the image moves only
            the arms and legs; "all": the paper's scheme, every step with every level.
        target_iterations: the targets-only steps of each frame with image_moves="limbs".
        target_step_tolerance: those steps end once a step's norm |dq| falls below this [rad]
            (None: always `target_iterations`); the frame's image steps carry the targets' levels
            above the image's and go on meeting them. 0.02 (default): on the real-motion benchmark
            (6 clips, 2 and 4 views, clean and with defects) every judged error within 0.21 mm of
            all five steps', the aggregates within 0.04 mm (docs/method.md, "Speed").
        step_tolerance: stop a frame's main solve (the image steps, or the blind steps without
            the image) once a step's norm |dq| falls below this [rad]; None: always `iterations`.
        image_stop: where a frame's image steps end. "peak" (default): once the image criterion
            no longer rises from one step to the next, back at the best of the two, or after
            `iterations` steps (Solver.solve's stop_at_peak); "count": always `iterations` steps,
            as in the paper. On the real-motion benchmark (2 views) "peak" took 4.7-8.0 steps a
            frame instead of 15, and all four elbows and knees went 12.2 -> 11.7 mm; on the real
            video (experiments/pose2sim_video.py) it kept climbing where the criterion still rose.
        stack: the priority levels and their tasks (tracking.stack); None: Stack.default(). An
            image task's criterion, step and views, when the stack gives them, replace
            `criterion`, `image_step` and the cameras; a posture task's weight `posture_weight`.
        swivel_cutoff_hz: with the frames' rate given to Tracker.track, the free elbows' and knees'
            swivels are low-passed at this cutoff [Hz] once every frame is solved, each joint kept
            on its frame's circle (tracking.swivel_smoothing); None: off. 6 Hz, the band of human
            joint motion (Winter); on the sweep (42 conditions, 2 views) 4-8 Hz left no condition
            worse by more than 1 mm (docs/sweep.md).
        read_ahead: where each frame's silhouettes are read and its support images built while
            the frame before is solved (readahead.frames_ahead): "process" (a forked child; a thread
            where fork is not available, off Linux), "thread", or "off" (in turn, on one thread:
            ibik batch's workers, one per core). The results are the same.
    """

    method: str = "qp"
    qp_solver: str = DEFAULT_QP_SOLVER
    iterations: int = 15
    first_frame_iterations: int = 100
    first_frame_starts: int = 1
    use_image: bool = True
    samples_per_segment: int = 6
    image_step: float = 0.05
    posture_weight: float = 1e-2
    mask_filter_radius: int = 0
    criterion: str = "two-way"
    axis_weight: float = 1.0
    axis_scale: float = 0.10
    swivel_search: bool = True
    swivel_cadence: int = 3
    swivel_refine: int = 4
    feet_by_ankle: bool = True
    image_moves: str = "limbs"
    target_iterations: int = 5
    target_step_tolerance: float | None = 0.02
    step_tolerance: float | None = None
    image_stop: str = "peak"
    stack: Stack | None = None
    swivel_cutoff_hz: float | None = SWIVEL_CUTOFF_HZ
    read_ahead: str = "process"


def _positive_or_none(value: object) -> bool:
    return value is None or (not isinstance(value, bool) and isinstance(value, (int, float))
                             and bool(np.isfinite(value)) and value > 0)


def check_settings(settings: TrackingSettings) -> None:
    """Refuse settings the tracker cannot run (one InputError naming the field); the stack's
    names and the QP backend are checked where they are read."""
    for name, value, choices in (("criterion", settings.criterion, CRITERIA),
                                 ("image_moves", settings.image_moves, IMAGE_MOVES),
                                 ("read_ahead", settings.read_ahead, READ_AHEAD_MODES),
                                 ("image_stop", settings.image_stop, IMAGE_STOPS)):
        if value not in choices:
            raise InputError(f"{name}: expected one of {', '.join(choices)}, found {value!r}")
    if int(settings.target_iterations) < 1:
        raise InputError(f"target_iterations: expected at least 1, found {settings.target_iterations}")
    if not _positive_or_none(settings.target_step_tolerance):
        raise InputError(f"target_step_tolerance: expected None or a positive number of radians, found "
                         f"{settings.target_step_tolerance!r}", parameter="target_step_tolerance")
    if not _positive_or_none(settings.swivel_cutoff_hz):
        raise InputError(f"swivel_cutoff_hz: expected None or a positive cutoff in Hz, found "
                         f"{settings.swivel_cutoff_hz!r}", parameter="swivel_cutoff_hz")
