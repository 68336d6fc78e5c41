"""Tracking a recorded sequence, frame after frame, each frame warm-started from the previous one.

The levels come from a priority stack (tracking.stack; `TrackingSettings.stack`, by default
ibik_pin/data/default_stack.toml): every keypoint present in the targets is an end-effector target
(level 1: pelvis and legs, level 2: trunk, head and arms); the image criterion is level 3 and a
light posture prior level 4. Each frame first takes a few steps with the targets alone, searches
the free elbows' and knees' swivels (tracking.swivel), then takes its image steps with the root,
spine, clavicles and neck held (Tracker._solve); once every frame is solved, the free elbows' and
knees' swivels are low-passed over the trial (tracking.swivel_smoothing). With `use_image=False` the
targets' levels run alone: the blind PIK baseline (same targets, iterations, initial state and limits).
"""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import cast

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import EmptySilhouetteWarning, InputError
from ibik_pin.feet import foot_point_joints
from ibik_pin.limits import JointLimits
from ibik_pin.model import BodyModel
from ibik_pin.names import unknown_names_message
from ibik_pin.readahead.frame_images import FrameImages, frame_images
from ibik_pin.readahead.frames_ahead import FrameImagesAhead
from ibik_pin.readahead.image_process import FrameRecords, can_fork
from ibik_pin.readahead.view_workers import read_ahead_workers
from ibik_pin.solvers import SolveResult, make_solver
from ibik_pin.tasks import FramePositionTask, ImageTask, PostureTask
from ibik_pin.tasks.base import GradientTask
from ibik_pin.tasks.image import support_at
from ibik_pin.tasks.segments import SegmentCriterion
from ibik_pin.tasks.silhouette_axis import SilhouetteAxisTask
from ibik_pin.tasks.weighted_sum import WeightedSum
from ibik_pin.tracking.compile_time import CompileTimer
from ibik_pin.tracking.first_frame import solve_first_frame
from ibik_pin.tracking.levels import StackPlan, StackTasks
from ibik_pin.tracking.outcomes import LevelOutcome, level_outcomes
from ibik_pin.tracking.result import TrackingResult
from ibik_pin.tracking.search_cadence import SearchCadence
from ibik_pin.tracking.settings import TrackingSettings, check_settings
from ibik_pin.tracking.stack import Stack
from ibik_pin.tracking.swivel import LIMB_ENDS, SwivelSearch, views_cross
from ibik_pin.tracking.swivel_smoothing import smooth_swivels
from ibik_pin.tracking.views import initial_configuration, support_caps, target_boxes
from ibik_pin.vision.segmentation import TemporalMajority

# A frame's silhouettes: one (H, W) bool mask per camera, in the cameras' order.
SilhouetteSource = Callable[[int], Sequence[np.ndarray]]


def _take_outcomes(result: TrackingResult, offloaded: dict[int, object]) -> None:
    """The level outcomes the image process's child sent back (their fields), into their frames."""
    for frame, outcomes in offloaded.items():
        result.level_outcomes[frame] = [LevelOutcome(*fields) for fields in cast(list, outcomes)]


class Tracker:
    """Solves a sequence of frames with one body, one camera set and one solver kept alive."""

    def __init__(self, body: BodyModel, cameras: Sequence = (), settings: TrackingSettings | None = None):
        self.body = body
        settings = settings or TrackingSettings()
        self.stack = settings.stack or Stack.default()
        self.stack.check_names(body.keypoints, [camera.name for camera in cameras] if cameras else None)
        image = self.stack.image
        # The stack's image task, where it says, overrides the settings and picks the cameras; its
        # qp_solver key, the QP backend.
        self.settings = replace(settings, criterion=image.criterion or settings.criterion,
                                image_step=image.step or settings.image_step) if image else settings
        if self.stack.qp_solver is not None:
            self.settings = replace(self.settings, qp_solver=self.stack.qp_solver)
        check_settings(self.settings)
        self.cameras = [camera for camera in cameras if image is None or image.views is None
                        or camera.name in image.views]
        model = body.model
        self.limits = JointLimits(model)
        self.solver = make_solver(self.settings.method, limits=self.limits, qp_solver=self.settings.qp_solver)
        self.image_task = ImageTask(body, (), samples_per_segment=self.settings.samples_per_segment,
                                    max_step_size=self.settings.image_step)
        self.axis_task = SilhouetteAxisTask(body, max_step_size=self.settings.image_step)
        terms: list[tuple[SegmentCriterion, float]] = [(self.image_task, 1.0)]
        if self.settings.criterion == "two-way":
            terms.append((self.axis_task, self.settings.axis_weight))
        # The gradient task of the image level: the paper's overlap, or the two-way sum.
        self.image_criterion: GradientTask = self.image_task
        if len(terms) > 1:
            self.image_criterion = WeightedSum([task for task, _ in terms], [weight for _, weight in terms],
                                               max_step_size=self.settings.image_step)
        self.swivel = SwivelSearch(body, terms, inside_silhouettes=self.image_task.inside_silhouettes,
                                   refine=int(self.settings.swivel_refine))
        self.search_cadence = SearchCadence(body, self.settings.swivel_cadence, self.swivel.min_radius)
        held = ~body.limb_coordinates
        # Holds the trunk during the image steps (_solve). A strict level: ik and liegeois, which merge
        # every level above the image into one task (eq. 3, 4), run the paper's scheme instead.
        self._trunk_hold = (PostureTask(model, coordinates=held)
                            if self.settings.image_moves == "limbs" and held.any()
                            and self.solver.name in ("qp", "stack") else None)
        # The cameras are fixed for the tracker's life, so whether the search can run is decided once.
        self._search_swivels = self.settings.swivel_search and views_cross(self.cameras)
        # Whether the image is followed: asked for, cameras to read, and a level of the stack for it.
        self.use_image = self.settings.use_image and bool(self.cameras) and image is not None
        self.tasks = StackTasks(self.stack, body, self.image_criterion if self.use_image else None,
                                self.settings.posture_weight, self._foot_point_joints)
        self._hint_tasks: dict[str, FramePositionTask] = {}

    def _foot_point_joints(self, name: str) -> np.ndarray | None:
        """The joints a foot point target moves (ibik_pin.feet); None: every joint."""
        return foot_point_joints(self.body, name) if self.settings.feet_by_ankle else None

    def _swivel_hints(self, configuration: Configuration, free: Sequence[str], frame: int) -> list[FramePositionTask]:
        """Position tasks that hold each free elbow and knee the frame searches (search_cadence) at
        its swivel hint (tracking.swivel); empty when no sample of any circle searched is clearly
        better than where the joint is."""
        searched = self.search_cadence.choose(frame, configuration, free)
        found = self.swivel.hints(configuration, searched) if searched else {}
        self.search_cadence.found(list(found))
        return [self._hint_task(name, position) for name, position in found.items()]

    def _hint_task(self, name: str, position: np.ndarray) -> FramePositionTask:
        """The position task that holds keypoint `name` at `position` (3,) [m] (one kept per keypoint)."""
        if name not in self._hint_tasks:
            self._hint_tasks[name] = FramePositionTask(self.body.model, self.body.keypoints[name])
        self._hint_tasks[name].set_target(position)
        return self._hint_tasks[name]

    def _solve(self, configuration: Configuration, plan: StackPlan, iterations: int | None = None,
               free: Sequence[str] = (), frame: int = 0) -> SolveResult:
        """Frame `frame`'s solve from configuration.q (`iterations` steps, default the settings').

        With image_moves="limbs", targets-only steps first, then the steps with the image under a
        top level that holds the root, spine, clavicles and neck where the targets put them. Why:
        the trunk's targets (Neck, shoulders) are rarely met exactly by the model, and their
        least-squares compromise has weak directions; the image level, pushing the arms every
        step, made the target level answer through the spine as well, and the trunk drifted along
        those directions frame after frame. On real boxing (2 views) the Neck ended 180 mm from
        its target and the shoulders 150 mm, where the targets alone kept them within 25 mm.
        The image is there for what the targets leave free, the limbs' swivels; holding the trunk
        leaves it exactly that.

        With the swivel search, `free` names the elbows and knees that are not targets this frame:
        their circles are searched once the targets are met (those the cadence picks:
        TrackingSettings.swivel_cadence), and the hints are a level just above
        the image's (StackPlan.with_level_above_image; with image_moves="all", the search follows
        the solve, which is then run again with the hints).

        Returns the solve's result, its level reports those of plan.solver_levels (no hold, no hints).
        """
        iterations = self.settings.iterations if iterations is None else iterations
        levels = plan.solver_levels
        tolerance = self.settings.step_tolerance
        if plan.image_level is None:
            return self.solver.solve(configuration, levels, iterations=iterations, tolerance=tolerance)
        search = self._search_swivels and bool(free)
        peak = self.settings.image_stop == "peak"
        # The targets' levels alone, for one closing step: a foot point's task sees only the ankle
        # (feet.foot_point_joints), so the image's last step, which turns the hip, moves the toe
        # where that task's null space does not show it; the closing step takes it back through
        # the ankle (toes 0.7 -> 11.9 mm on real walking without it, 2 views).
        above_image = list(levels[:plan.image_level])
        if self._trunk_hold is None:
            solved = self.solver.solve(configuration, levels, iterations=iterations, tolerance=tolerance,
                                       stop_at_peak=peak)
            hints = self._swivel_hints(configuration, free, frame) if search else []
            if hints:
                self.solver.solve(configuration, plan.with_level_above_image(hints), iterations=iterations,
                                  stop_at_peak=peak)
            if above_image:
                self.solver.solve(configuration, above_image, iterations=1)
            return solved
        self.solver.solve(configuration, plan.blind_levels(), iterations=int(self.settings.target_iterations),
                          tolerance=self.settings.target_step_tolerance)
        self._trunk_hold.set_reference(configuration.q)
        hints = self._swivel_hints(configuration, free, frame) if search else []
        hinted = plan.with_level_above_image(hints) if hints else levels
        solved = self.solver.solve(configuration, [[self._trunk_hold], *hinted], iterations=iterations,
                                   tolerance=tolerance, stop_at_peak=peak)
        self.solver.solve(configuration, [[self._trunk_hold], *above_image], iterations=1)
        reports = solved.levels[1:]
        if hints:
            del reports[plan.image_level]  # the hints' level, inserted just above the image's
        return dataclasses.replace(solved, levels=reports)

    def track(
        self,
        names: list[str],
        targets: np.ndarray,
        silhouettes: SilhouetteSource | None = None,
        progress: Callable[[], None] | None = None,
        frame_rate_hz: float | None = None,
    ) -> TrackingResult:
        """Solve every frame.

        Args:
            names: target keypoint names (each must be a keypoint of the body).
            targets: (F, K, 3) target positions [m] in the model's frame; NaN = absent that frame.
            silhouettes: frame index -> one mask per camera; needed when the image is used.
            progress: called once per solved frame.
            frame_rate_hz: the frames' rate (taken as consecutive): with the image, the free elbows'
                and knees' swivels are then low-passed at settings.swivel_cutoff_hz (tracking.
                swivel_smoothing, timed in solve_seconds); None: each frame's own solution is kept.
        """
        unknown = [name for name in names if name not in self.body.keypoints]
        if unknown:
            raise InputError(
                f"names: unknown keypoint name(s) {unknown_names_message(unknown, list(self.body.keypoints))}; "
                "known keypoints: " + ", ".join(self.body.keypoints), parameter="names"
            )
        targets = np.asarray(targets, dtype=float)
        if targets.ndim != 3 or targets.shape[1:] != (len(names), 3):
            raise InputError(f"targets must have shape (F, {len(names)}, 3), got {targets.shape}")
        use_image = self.use_image
        frame_count = targets.shape[0]
        # The silhouettes the image level reads (temporally filtered if asked); None without the image.
        source: SilhouetteSource | None = None
        if use_image:
            if silhouettes is None:
                raise InputError("silhouettes: the image criterion needs them (a function of the frame index "
                                 "giving one mask per camera); give them, or settings.use_image=False",
                                 parameter="silhouettes")
            source = silhouettes
            if self.settings.mask_filter_radius > 0:
                source = TemporalMajority(silhouettes, frame_count, self.settings.mask_filter_radius)
        plan = self.tasks.plan(names)
        levels = plan.solver_levels
        report_index = plan.report_index(self.solver)
        keypoint_names = list(self.body.keypoints)
        keypoint_ids = self.body.frame_ids(keypoint_names)
        target_ids = np.array([self.tasks.target_tasks[name].frame_id for name in names])
        result = TrackingResult(
            q=np.zeros((frame_count, self.body.model.nq)),
            keypoint_names=keypoint_names,
            keypoints=np.zeros((frame_count, len(keypoint_names), 3)),
            target_residuals=np.zeros(frame_count),
            target_names=list(names),
            target_distances=np.full((frame_count, len(names)), np.nan),
            overlap=np.full((frame_count, len(self.cameras)), np.nan),
            inside_fraction=np.full((frame_count, len(self.cameras)), np.nan),
            level_names=plan.names,
            camera_names=[camera.name for camera in self.cameras] if use_image else [],
        )
        configuration = Configuration(self.body.model, initial_configuration(self.body, names, targets[0]))
        self.search_cadence.reset()
        caps = support_caps(self.cameras, configuration.q[:3]) if use_image else []
        axis_scales = support_caps(self.cameras, configuration.q[:3], self.settings.axis_scale) if use_image else []
        # Frame t + 1's silhouettes are read and its support images built while frame t is solved.
        prepare = None if source is None else functools.partial(
            frame_images, source, self.cameras, caps, axis_scales if self.settings.criterion == "two-way" else None,
            target_boxes=target_boxes(self.cameras, targets),
            # Large views on threads in the child process (it has its own GIL); beside the solver, in a
            # thread, one view at a time.
            workers=(read_ahead_workers([camera.size for camera in self.cameras])
                     if self.settings.read_ahead == "process" and can_fork() else 1))
        loop_started = time.perf_counter()
        records = silhouettes if isinstance(silhouettes, FrameRecords) else None
        outcomes_job = functools.partial(self._outcomes_in_copy, plan, names, targets, report_index, configuration)
        compiling, solves = CompileTimer(), []
        with compiling.recording(), FrameImagesAhead(prepare, frame_count, self.settings.read_ahead, records,
                                                     outcomes_job) as images:
            for frame in range(frame_count):
                present = self._set_targets(names, targets[frame])
                result.dropped_targets.append([n for n, p in zip(names, present, strict=True) if not p])
                disabled: list[str] = []
                if source is not None:  # the image is used
                    prepared = images.get(frame)
                    disabled = prepared.disabled
                    self._set_images(prepared)
                result.disabled_views.append(disabled)
                self.tasks.start_frame(configuration)
                frame_start = configuration.q.copy()
                # The elbows and knees this frame leaves to the image (for the swivel search).
                free = [name for name in LIMB_ENDS if name not in names or not present[names.index(name)]]
                started = time.perf_counter()
                if frame == 0:
                    solved = solve_first_frame(self.solver, configuration, levels, plan.image_criterion,
                                               self.settings.first_frame_iterations, self.settings.first_frame_starts,
                                               blind_levels=plan.blind_levels(),
                                               solve=lambda configuration, _levels, iterations, free=free: self._solve(
                                                   configuration, plan, iterations, free=free))
                else:
                    solved = self._solve(configuration, plan, free=free, frame=frame)
                result.level_reports.append(solved.levels)
                result.iterations.append(int(solved.iterations))
                solves.append((started, time.perf_counter()))
                result.solve_seconds += solves[-1][1] - started
                result.q[frame] = configuration.q
                result.keypoints[frame] = configuration.frame_positions(keypoint_ids)
                # Each present target's distance, read in one call (as FramePositionTask.compute_error).
                errors = np.linalg.norm(configuration.frame_positions(target_ids[present])
                                        - targets[frame, present], axis=1)
                result.target_distances[frame, present] = errors
                result.target_residuals[frame] = np.mean(errors) if errors.size else np.nan
                if use_image:
                    result.overlap[frame], result.inside_fraction[frame] = self._overlap_per_view(configuration,
                                                                                                  disabled)
                result.limit_hits.append(self.limits.at_limit(configuration.q))
                # The level outcomes: in the image process's child when it is ahead (the same values,
                # from its copy of this tracker), else here.
                statuses = tuple(report.status for report in solved.levels)
                if images.offload(frame, (frame_start, configuration.q.copy(), statuses)):
                    result.level_outcomes.append([])  # filled when the child's answer comes back
                else:
                    result.level_outcomes.append(level_outcomes(plan, configuration, statuses, report_index,
                                                                self.solver.damping))
                _take_outcomes(result, images.results())
                if progress is not None:
                    progress()
            _take_outcomes(result, images.finish_jobs())
        cutoff = self.settings.swivel_cutoff_hz
        if use_image and frame_rate_hz is not None and cutoff is not None:
            started = time.perf_counter()
            result.swivel_smoothing = self._smooth_swivels(result, plan, names, targets, configuration,
                                                           float(frame_rate_hz), float(cutoff))
            result.solve_seconds += time.perf_counter() - started
        result.loop_seconds = time.perf_counter() - loop_started
        result.compile_seconds = compiling.seconds
        result.solve_compile_seconds = compiling.seconds_within(solves)
        return result

    def _outcomes_in_copy(self, plan: StackPlan, names: list[str], targets: np.ndarray, report_index: list,
                          configuration: Configuration, frame: int, images: FrameImages | None,
                          payload: tuple) -> list[tuple]:
        """A frame's level_outcomes in the image process's child (FrameImagesAhead.offload), on its
        copy of this tracker set as track() had it at the frame's solution: the frame's targets, its
        images, the postures' previous-frame reference. `payload`: q at the frame's start, its
        solution, the statuses of the solver's level reports. Each outcome comes back as the tuple
        of its fields (a tenth of a dataclass's unpickling time)."""
        frame_start, solution, statuses = payload
        if images is None:
            raise RuntimeError(f"the images of frame {frame} are no longer kept for its level outcomes")
        self._set_targets(names, targets[frame])
        self._set_images(images)
        configuration.update(frame_start)
        self.tasks.start_frame(configuration)
        configuration.update(solution)
        return [dataclasses.astuple(outcome)
                for outcome in level_outcomes(plan, configuration, statuses, report_index, self.solver.damping)]

    def _smooth_swivels(self, result: TrackingResult, plan: StackPlan, names: list[str], targets: np.ndarray,
                        configuration: Configuration, rate_hz: float, cutoff_hz: float) -> dict:
        """tracking.swivel_smoothing.smooth_swivels, each frame's moved joints held at their places
        below the targets' levels (the trunk held, as for the image steps), then the closing step."""
        keypoint_ids = self.body.frame_ids(result.keypoint_names)
        target_ids = np.array([self.tasks.target_tasks[name].frame_id for name in names])
        above_image = list(plan.solver_levels[:plan.image_level])

        def move(frame: int, places: dict[str, np.ndarray]) -> None:
            configuration.update(result.q[frame])
            present = self._set_targets(names, targets[frame])
            levels: list[Sequence] = [*above_image, [self._hint_task(name, place) for name, place in places.items()]]
            if self._trunk_hold is not None:
                self._trunk_hold.set_reference(configuration.q)
                levels = [[self._trunk_hold], *levels]
            self.solver.solve(configuration, levels, iterations=int(self.settings.target_iterations),
                              tolerance=self.settings.target_step_tolerance)
            # The closing step of _solve: the toes and heels back through the ankles.
            self.solver.solve(configuration, levels[:-1], iterations=1)
            result.q[frame] = configuration.q
            result.keypoints[frame] = configuration.frame_positions(keypoint_ids)
            errors = np.linalg.norm(configuration.frame_positions(target_ids[present]) - targets[frame, present],
                                    axis=1)
            result.target_distances[frame, present] = errors
            result.target_residuals[frame] = np.mean(errors) if errors.size else np.nan

        return smooth_swivels(result.keypoint_names, result.keypoints, names, targets, rate_hz, cutoff_hz, move)

    def _set_targets(self, names: list[str], frame_targets: np.ndarray) -> np.ndarray:
        """Give each target task its position of the frame (K, 3), or switch it off where absent (NaN);
        returns which are present (K,)."""
        present = np.all(np.isfinite(frame_targets), axis=1)
        for k, name in enumerate(names):
            self.tasks.target_tasks[name].set_target(frame_targets[k] if present[k] else None)
        return present

    def _set_images(self, images: FrameImages) -> None:
        """Give the image terms the frame's views (empty ones are reported per frame, not warned of)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EmptySilhouetteWarning)
            self.image_task.set_views(images.views)
            if images.axis_views is not None:
                self.axis_task.set_views(images.axis_views)

    def _overlap_per_view(self, configuration: Configuration, disabled: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """Per view, the mean support at the skeleton's sample points [px] and the fraction inside [0-1]."""
        points = self.image_task.sample_points(configuration)
        overlap = np.full(len(self.cameras), np.nan)
        inside = np.full(len(self.cameras), np.nan)
        for index, view in enumerate(self.image_task.views):
            if view.camera.name in disabled:
                continue
            values = support_at(view, points)
            overlap[index], inside[index] = float(np.mean(values)), float(np.mean(values > 0.0))
        return overlap, inside
