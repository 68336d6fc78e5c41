"""What `ibik track` did, as a typed record written to OUTDIR/report.json.

Frame numbering: every key or list indexed by frame follows the targets' TRC: a dictionary keyed
by frame uses the TRC's ``Frame#`` (the first row of a Pose2Sim or OpenSim TRC is frame 1), a
``per_frame`` list holds one value per TRC row, in file order. Lengths are in metres (keys ending
in ``_m``), rates in Hz, times in seconds. Values that do not exist (a target absent from every
frame, a disabled view) are written as JSON null, never as a bare NaN.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ibik_pin.app.axes import AxesChoice, TrcAxesReport
from ibik_pin.app.input_reports import SilhouetteQuality, TriangulationReport
from ibik_pin.app.report_units import FRAME_NUMBERING, UNITS
from ibik_pin.app.video_people import PeopleReport
from ibik_pin.io.files import json_ready, strict_json, write_text_atomically
from ibik_pin.tracking.result import TrackingResult
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.vision.extrinsics_refit import ExtrinsicsRefit


def _finite_or_none(value: float | np.floating) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass
class ResidualStats:
    """Distances of model keypoints to their targets over the frames [m].

    Attributes:
        mean: mean over the frames where the target is present [m]; None if never present.
        median: median over the same frames [m].
        max: largest [m].
        per_frame: one value per frame [m]; None where the target is absent.
    """

    mean: float | None
    median: float | None
    max: float | None
    per_frame: list[float | None]

    @classmethod
    def from_values(cls, values_m: np.ndarray) -> ResidualStats:
        """Statistics of (F,) distances [m], NaN where absent."""
        values_m = np.asarray(values_m, dtype=float)
        present = values_m[np.isfinite(values_m)]
        if present.size == 0:
            return cls(None, None, None, [None] * len(values_m))
        return cls(float(np.mean(present)), float(np.median(present)), float(np.max(present)),
                   [_finite_or_none(value) for value in values_m])


@dataclass
class SolverLevelsReport:
    """What each level of the priority stack got, frame by frame (tracking.outcomes).

    Attributes:
        stack: where the stack came from: "default" or the stack file.
        levels: the stack's levels, highest first.
        status_per_frame: per level, the solver's status at each frame's last step: "solved";
            "relaxed" (a least-squares optimum with a residual: unreachable under the higher
            levels or the joint limits); "failed" (the QP backend failed, the level was skipped);
            "empty" (nothing to do: no enabled task, no null space left or a zero gradient, or a
            level the scheme does not solve). Weighted levels share their solver level's status.
        frames_per_status: per level, how many frames ended in each status.
        residual_per_frame: per level, sqrt(sum w |e|^2) of its least-squares tasks at each
            frame's solution (m for targets and the centre of mass, rad for a posture); None for
            the image level.
        sacrificed_per_frame: per level, the part of its residual that the levels above keep it
            from removing, at each frame's solution (its residual's units; for the image level the
            share of its gradient they take, 0-1).
        criterion_per_frame: per image level, its criterion h(q) at each frame's solution.
        mean_residual: per level, the mean of residual_per_frame (None if never defined).
        mean_sacrificed: per level, the mean of sacrificed_per_frame (None if never defined).
    """

    stack: str = "default"
    levels: list[str] = field(default_factory=list)
    status_per_frame: dict[str, list[str]] = field(default_factory=dict)
    frames_per_status: dict[str, dict[str, int]] = field(default_factory=dict)
    residual_per_frame: dict[str, list[float | None]] = field(default_factory=dict)
    sacrificed_per_frame: dict[str, list[float | None]] = field(default_factory=dict)
    criterion_per_frame: dict[str, list[float | None]] = field(default_factory=dict)
    mean_residual: dict[str, float | None] = field(default_factory=dict)
    mean_sacrificed: dict[str, float | None] = field(default_factory=dict)

    @classmethod
    def from_result(cls, result: TrackingResult, stack: str = "default") -> SolverLevelsReport:
        names = list(result.level_names)
        frames = result.level_outcomes

        def series(attribute: str) -> dict[str, np.ndarray]:
            return {name: np.array([getattr(frame[index], attribute) for frame in frames], dtype=float)
                    for index, name in enumerate(names)}

        def listed(values: dict[str, np.ndarray]) -> dict[str, list[float | None]]:
            return {name: [_finite_or_none(value) for value in column] for name, column in values.items()}

        def means(values: dict[str, np.ndarray]) -> dict[str, float | None]:
            return {name: _finite_or_none(np.mean(column[np.isfinite(column)])) if np.isfinite(column).any()
                    else None for name, column in values.items()}

        status = {name: [frame[index].status for frame in frames] for index, name in enumerate(names)}
        counts = {name: {kind: values.count(kind) for kind in sorted(set(values))} for name, values in status.items()}
        residual, sacrificed, criterion = series("residual"), series("sacrificed"), series("criterion")
        return cls(stack, names, status, counts, listed(residual), listed(sacrificed),
                   {name: values for name, values in listed(criterion).items() if any(v is not None for v in values)},
                   means(residual), means(sacrificed))


@dataclass
class TrackingReport:
    """Everything report.json holds; the field names are its keys (see the module docstring).

    Attributes:
        frames: number of frames tracked.
        frame_numbering: how frames are numbered in this report.
        frame_numbers: (F,) the TRC's frame numbers.
        frame_rate_hz: the TRC's data rate [Hz].
        times_s: (F,) the TRC's times [s].
        method: solver scheme.
        qp_solver: the level QP's backend with the "qp" scheme; None with the others.
        image: whether the image criterion was used.
        criterion: the image criterion ("paper" or "two-way").
        iterations_per_frame: solver steps per frame after the first.
        mean_iterations_per_frame: steps the main solves took, mean over the frames after the
            first (below iterations_per_frame when image_stop or step_tolerance ends them early).
        step_tolerance: the settings' step_tolerance [rad], or None.
        target_step_tolerance: the settings' target_step_tolerance [rad], or None.
        image_stop: the settings' image_stop ("peak" or "count").
        mask_filter_radius: temporal majority filter radius of the silhouettes [frames].
        solve_frames_per_second: frames solved per second of solver time [Hz]; None if unmeasured.
        frames_per_second: frames per second of the whole frame loop, silhouettes read and support
            images built included [Hz]; None if unmeasured.
        cameras: the cameras whose images were used (empty when blind).
        trc_axes: the TRC's axis convention and how it was chosen.
        end_effector_residual_m: per frame, the mean distance of the present targets to their
            keypoints, and its statistics over the frames [m].
        keypoint_residual_m: per target keypoint, its distance to its target [m].
        overlap_per_view: per camera, the image criterion at each frame's solution [px] (None when
            the view was disabled): a mean capped signed distance, see :data:`UNITS`.
        joint_limit_hits: TRC frame number -> joints at a limit (frames without any omitted).
        frames_with_dropped_targets: TRC frame number -> targets absent in that frame (outliers
            included).
        frames_with_outlier_targets: TRC frame number -> targets dropped in that frame because they
            lay metres from the rest of the body (app.input_checks.drop_outlier_targets).
        frames_with_disabled_views: TRC frame number -> cameras whose silhouette was empty.
        solver_levels: per level of the priority stack, its status, residual and sacrifice at
            each frame.
        inside_fraction_per_view: per camera, the fraction of the skeleton inside the silhouette
            at each frame [0-1] (None when the view was disabled).
        solve_seconds: wall time of the solves [s].
        compile_seconds: wall time spent compiling the numeric kernels during the frame loop (a
            first run on a machine) [s]; the frame rates leave it out.
        loop_seconds: wall time of the whole frame loop [s] (see :data:`UNITS`).
        silhouettes: how well each camera's silhouettes hold the projected targets, and their
            area over time (app.input_reports.SilhouetteQuality); None without silhouettes.
        triangulation: with --videos and no --targets, how the targets were triangulated
            (app.input_reports.TriangulationReport); None when they were given.
        extrinsics: the check of the cameras' poses against each other's detections, and the
            re-fitted ones (vision.extrinsics_refit.ExtrinsicsRefit); None when it did not run.
        trial_lengths: with --trial-lengths reach, each limb segment's static and trial length and
            their change [mm], and per limb what decided (subject.trial_lengths.TrialLengths.report);
            None otherwise.
        target_filter: how --target-filter low-passed the targets, per keypoint the cutoff [Hz] and
            change [mm] (tracking.target_filter.TargetFilterResult.report); None if not reported.
        swivel_smoothing: how the free elbows' and knees' swivels were low-passed over the trial
            (tracking.swivel_smoothing; TrackingResult.swivel_smoothing); None when it did not run.
        diagnosis: what the run judged of its own evidence: suspect views and frames, the figures
            and thresholds (app.diagnosis.Diagnosis); None when not judged (the report of a run
            made outside `ibik track`).
        people: with --videos and MediaPipe, who was in the videos and whom the run followed
            (app.video_people.PeopleReport); None otherwise.
        stage_seconds: wall time of each stage of the run [s] (see :data:`UNITS`).
        detection_seconds: decoding and detection summed over the views' worker processes [s].
        end_to_end_seconds: wall time of the whole run, the command's start to the outputs [s] (UNITS).
        end_to_end_frames_per_second: frames per second of end_to_end_seconds, detection included.
        warnings: every warning the run gave on stderr, in order, each once.
        kept_user_files: the files of an earlier output that ibik did not write, kept in OUTDIR.
        units: :data:`UNITS`, written into the file so that it describes itself.
    """

    frames: int
    frame_numbering: str
    frame_numbers: list[int]
    frame_rate_hz: float
    times_s: list[float]
    method: str
    qp_solver: str | None
    image: bool
    criterion: str
    iterations_per_frame: int
    mask_filter_radius: int
    solve_frames_per_second: float | None
    cameras: list[str]
    trc_axes: TrcAxesReport
    end_effector_residual_m: ResidualStats
    keypoint_residual_m: dict[str, ResidualStats]
    overlap_per_view: dict[str, list[float | None]]
    joint_limit_hits: dict[str, list[str]]
    frames_with_dropped_targets: dict[str, list[str]]
    frames_with_disabled_views: dict[str, list[str]]
    solver_levels: SolverLevelsReport = field(default_factory=SolverLevelsReport)
    inside_fraction_per_view: dict[str, list[float | None]] = field(default_factory=dict)
    solve_seconds: float | None = None
    compile_seconds: float | None = None
    frames_per_second: float | None = None
    loop_seconds: float | None = None
    frames_with_outlier_targets: dict[str, list[str]] = field(default_factory=dict)
    mean_iterations_per_frame: float | None = None
    step_tolerance: float | None = None
    target_step_tolerance: float | None = None
    image_stop: str | None = None
    silhouettes: SilhouetteQuality | None = None
    triangulation: TriangulationReport | None = None
    extrinsics: ExtrinsicsRefit | None = None
    trial_lengths: dict[str, Any] | None = None
    target_filter: dict[str, Any] | None = None
    swivel_smoothing: dict[str, Any] | None = None
    diagnosis: dict[str, Any] | None = None
    people: PeopleReport | None = None
    stage_seconds: dict[str, float] | None = None
    detection_seconds: dict[str, float] | None = None
    end_to_end_seconds: float | None = None
    end_to_end_frames_per_second: float | None = None
    warnings: list[str] = field(default_factory=list)
    kept_user_files: list[str] = field(default_factory=list)
    units: dict[str, str] = field(default_factory=lambda: dict(UNITS))

    @classmethod
    def from_tracking(
        cls,
        result: TrackingResult,
        settings: TrackingSettings,
        camera_names: list[str],
        frame_numbers: np.ndarray,
        times_s: np.ndarray,
        frame_rate_hz: float,
        axes: AxesChoice,
        outliers: np.ndarray | None = None,
    ) -> TrackingReport:
        """The report of one tracking run.

        Args:
            result: what the tracker returned.
            settings: how it solved.
            camera_names: the cameras whose images were used, in the order of result.overlap's
                columns (empty when blind).
            frame_numbers: (F,) the TRC's frame numbers; times_s: (F,) its times [s].
            frame_rate_hz: the TRC's data rate [Hz].
            axes: the TRC's axis convention.
            outliers: (F, T) bool, the targets dropped as outliers (columns: result.target_names).
        """
        numbers = [int(number) for number in frame_numbers]

        def by_frame(per_frame: list[list[str]]) -> dict[str, list[str]]:
            return {str(number): list(items) for number, items in zip(numbers, per_frame, strict=True) if items}

        return cls(
            frames=len(numbers),
            frame_numbering=FRAME_NUMBERING,
            frame_numbers=numbers,
            frame_rate_hz=float(frame_rate_hz),
            times_s=[float(time) for time in times_s],
            method=settings.method,
            qp_solver=settings.qp_solver if settings.method == "qp" else None,
            image=bool(settings.use_image and camera_names),
            criterion=settings.criterion,
            iterations_per_frame=settings.iterations,
            mask_filter_radius=settings.mask_filter_radius,
            solve_frames_per_second=_finite_or_none(result.solve_frames_per_second),
            cameras=list(camera_names),
            trc_axes=TrcAxesReport.from_choice(axes, frame_numbers),
            end_effector_residual_m=ResidualStats.from_values(result.target_residuals),
            keypoint_residual_m={name: ResidualStats.from_values(result.target_distances[:, index])
                                 for index, name in enumerate(result.target_names)},
            overlap_per_view={name: [_finite_or_none(value) for value in result.overlap[:, index]]
                              for index, name in enumerate(camera_names)},
            joint_limit_hits=by_frame(result.limit_hits),
            frames_with_dropped_targets=by_frame(result.dropped_targets),
            frames_with_disabled_views=by_frame(result.disabled_views),
            solver_levels=SolverLevelsReport.from_result(
                result, "default" if settings.stack is None else settings.stack.source),
            inside_fraction_per_view={name: [_finite_or_none(value) for value in result.inside_fraction[:, index]]
                                      for index, name in enumerate(camera_names)
                                      if result.inside_fraction.shape == result.overlap.shape},
            solve_seconds=_finite_or_none(result.solve_seconds),
            compile_seconds=_finite_or_none(result.compile_seconds),
            frames_per_second=_finite_or_none(result.frames_per_second),
            loop_seconds=_finite_or_none(result.loop_seconds),
            mean_iterations_per_frame=(float(np.mean(result.iterations[1:])) if len(result.iterations) > 1
                                       else None),
            step_tolerance=settings.step_tolerance,
            target_step_tolerance=settings.target_step_tolerance,
            image_stop=settings.image_stop,
            swivel_smoothing=result.swivel_smoothing,
            frames_with_outlier_targets={} if outliers is None else by_frame(
                [[name for name, out in zip(result.target_names, row, strict=True) if out] for row in outliers]),
        )

    def to_dict(self) -> dict[str, Any]:
        """The report as plain JSON values (NaN and infinities as None)."""
        return json_ready(dataclasses.asdict(self))

    def to_json(self) -> str:
        """Strict JSON text (no NaN or Infinity tokens), indented."""
        return strict_json(self.to_dict())

    def write(self, path: str | Path) -> None:
        """Write to_json() to `path` atomically."""
        write_text_atomically(path, self.to_json())

    def __getitem__(self, key: str) -> Any:
        """report.json's value for `key`, for callers that read the report as they read the file."""
        return self.to_dict()[key]

    def keypoints_worst_first(self) -> list[tuple[str, ResidualStats]]:
        """The target keypoints by decreasing mean residual (never-present ones last)."""
        return sorted(self.keypoint_residual_m.items(),
                      key=lambda item: -item[1].mean if item[1].mean is not None else math.inf)

    def summary_lines(self) -> list[str]:
        """For the console: frames, speed and mean end-effector residual [mm], then each target
        keypoint's mean and largest residual [mm], worst first."""
        speed = (f"{self.frames_per_second:.1f} frames/s" if self.frames_per_second is not None
                 else "an unmeasured speed")
        if self.solve_frames_per_second is not None:
            speed += f" (the solves alone {self.solve_frames_per_second:.1f})"
        overall = self.end_effector_residual_m.mean
        lines = [f"{self.frames} frames at {speed}, mean end-effector residual "
                 + (f"{1000 * overall:.1f} mm" if overall is not None else "not measured (no target present)")]
        width = max((len(name) for name in self.keypoint_residual_m), default=0)
        lines.append("mean residual per target keypoint [mm], worst first (max in brackets):")
        for name, stats in self.keypoints_worst_first():
            if stats.mean is None or stats.max is None:
                lines.append(f"  {name:<{width}}  absent in every frame")
            else:
                lines.append(f"  {name:<{width}}  {1000 * stats.mean:7.1f}  ({1000 * stats.max:.1f})")
        return lines


__all__ = ["ResidualStats", "SolverLevelsReport", "TrackingReport", "TrcAxesReport"]
