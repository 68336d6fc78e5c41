"""What every figure of report.json means: the unit and meaning written as its "units" entry, and
how its frames are numbered (ibik_pin.app.report writes both)."""

from __future__ import annotations

from ibik_pin.solvers import LevelStatus

__all__ = ["FRAME_NUMBERING", "UNITS"]

FRAME_NUMBERING = (
    "frame keys are the targets TRC's Frame# (the first row of a Pose2Sim/OpenSim TRC is frame 1); "
    "per_frame lists hold one value per TRC row, in file order"
)


#: report.json's "units": the unit and meaning of every figure the report holds.
UNITS = {
    "frame_numbers": "the TRC's Frame# (counted from 1, as the TRC counts); keys of the frame dictionaries too",
    "frame_rate_hz": "Hz: the targets TRC's DataRate",
    "times_s": "s: the targets TRC's Time column",
    "solve_seconds": "s: wall time of the solves alone (no reading or writing), compilation included",
    "compile_seconds": ("s: wall time the tracking process spent compiling its numeric kernels (Numba) during "
                        "the frame loop: seconds on a machine's first run, 0 once they are cached on disk; a "
                        "read-ahead child process's compilation is not counted"),
    "solve_frames_per_second": "frames per second of solve_seconds, compilation left out",
    "loop_seconds": ("s: wall time of the whole frame loop: the solves, reading the silhouettes, building the "
                     "support images and medial axes (ahead of the solve: by default in a child process), each "
                     "frame's checks"),
    "frames_per_second": "frames per second of loop_seconds, compilation left out",
    "iterations_per_frame": "solver steps per frame after the first",
    "mean_iterations_per_frame": "solver steps of a frame's main solve, mean over the frames after the first",
    "step_tolerance": "rad: the step norm under which a frame's main solve stops (null: never early)",
    "target_step_tolerance": "rad: the step norm under which a frame's targets-only steps stop (null: never early)",
    "image_stop": "where the image steps end: peak (the criterion stopped rising) or count (iterations_per_frame)",
    "mask_filter_radius": "frames on each side of the temporal majority filter",
    "end_effector_residual_m": "m: per frame, the mean distance of the present targets to the model's keypoints",
    "end_effector_residual_m.per_frame": "m: each frame's value (null where no target was present)",
    "end_effector_residual_m.mean": "m: mean of per_frame over the frames (those of keypoint_residual_m too)",
    "end_effector_residual_m.median": "m: median of per_frame over the frames",
    "end_effector_residual_m.max": "m: largest of per_frame",
    "keypoint_residual_m": "m: per target keypoint, the distance of the model's keypoint to its target",
    "overlap_per_view": ("px: the paper's image criterion h (eq. 5-6) at each frame's solution, the mean over "
                         "the skeleton's sample points of the silhouette's capped signed distance (positive "
                         "inside, capped at about a limb's half-width; negative outside); higher is better; "
                         "not a 0-1 overlap: see inside_fraction_per_view"),
    "inside_fraction_per_view": "0-1: the fraction of the skeleton's sample points that project inside the silhouette",
    "trc_axes.inside_images": "0-1",
    "trc_axes.inside_silhouettes": "0-1",
    "trc_axes.upright_cosine": "-1 to 1",
    "silhouettes": "null without silhouettes; otherwise the silhouettes.* entries",
    "triangulation": "null when --targets were given; otherwise the triangulation.* entries",
    "silhouettes.segmenter": "where the silhouettes came from: mediapipe, mog2 (from --videos) or masks (given)",
    "silhouettes.targets_inside_per_view": "0-1: per frame, the share of the projected targets inside the silhouette",
    "silhouettes.targets_inside_mean": "0-1: per camera, the mean of targets_inside_per_view over the frames",
    "silhouettes.mask_area_per_view": "px: per frame, the silhouette's area",
    "triangulation.file": "the triangulated TRC written with the outputs",
    "triangulation.keypoints": "the keypoints it holds",
    "triangulation.tracked_keypoints": "those of them used as targets",
    "triangulation.frames_swapped_per_view": ("per camera, the number of frames whose left and right the detector "
                                              "had exchanged (resolved across views)"),
    "triangulation.reprojection_median_m": "m: reprojection error at the point's depth, median over the frames",
    "triangulation.landmarks_used_per_view": "0-1",
    "extrinsics": ("null unless MediaPipe's landmarks from three cameras or more were checked against each other; "
                   "the cameras turned by --refit-cameras are written to calibration_refitted.toml"),
    "extrinsics.reprojection_px": ("px: per camera, median distance from its detections to the landmarks the other "
                                   "views triangulate, projected, as calibrated; reprojection_after_px: re-fitted"),
    "people": "null unless MediaPipe ran on --videos; otherwise the people.* entries",
    "people.found": "the number of people two views or more agree on (app.video_people)",
    "people.tracked": "the person followed, numbered as people.view_frames ranks them (1 = the most seen)",
    "people.rule": "how the default person (--person auto) is chosen",
    "people.view_frames": "per person, most seen first: detections associated to that person, over views and frames",
    "people.frames_triangulated": "per person: frames where two views or more agree on that person",
    "people.unassociated_per_view": "per camera: detections no other view confirms, left out of every person",
    "people.pair_error_median_m": "m: median reprojection error, at the person's depth, of the associated detections",
    "people.max_people": "trackers per view: the most people followed at once in a view",
    "people.detect_height": "px: the height frames were fed to MediaPipe at (0: full size)",
    "people.workers": "processes the views were detected in (at most one per camera, at most the usable cores)",
    "stage_seconds": ("s: wall time of each stage: startup (the `ibik` command's start and imports; absent when "
                      "another program runs the job), detection (decoding and MediaPipe, the views in parallel "
                      "processes), association (people across views and time), triangulation (with the cameras' "
                      "check), calibration (the subject's lengths), solve (the frame loop), outputs (the files "
                      "written); absent stages left out"),
    "stage_seconds.startup": "s: see stage_seconds",
    "stage_seconds.detection": "s: see stage_seconds",
    "stage_seconds.association": "s: see stage_seconds",
    "stage_seconds.triangulation": "s: see stage_seconds",
    "stage_seconds.calibration": "s: see stage_seconds",
    "stage_seconds.solve": "s: see stage_seconds",
    "stage_seconds.outputs": "s: see stage_seconds",
    "detection_seconds": "null without MediaPipe on --videos; otherwise detection_seconds.*",
    "detection_seconds.decode": "s: decoding the videos, summed over the views (processor time in the workers)",
    "detection_seconds.detection": "s: MediaPipe, summed over the views (processor time in the workers)",
    "end_to_end_seconds": ("s: wall time of the whole run as its user waits for it: from the `ibik` command's start "
                           "(its imports included) to the written outputs (report.json and the move into OUTDIR, "
                           "a few ms, left out); from the call to run_track when another program runs the job"),
    "end_to_end_frames_per_second": ("frames per second of end_to_end_seconds: detection, triangulation, "
                                     "calibration and solve included (frames_per_second is the frame loop's)"),
    "extrinsics.diagnosis": ("per camera: 'agrees', or why it disagrees with the others (more than twice their "
                             "median): another person overlapping the subject, a detector that switched people, "
                             "or the camera itself (moved or miscalibrated); vision.camera_diagnosis"),
    "extrinsics.turn_deg": "deg: how far each re-fitted camera turned about its centre",
    "extrinsics.refitted": "the cameras turned by --refit-cameras",
    "extrinsics.reprojection_after_px": "px: extrinsics.reprojection_px with the re-fitted cameras",
    "frames": "the number of frames tracked (rows of the targets TRC)",
    "frame_numbering": "how the frames of this report are numbered",
    "image": "true when the image criterion was used (false: the blind baseline, or no view)",
    "criterion": "the image criterion: paper (the overlap of eq. 5-6) or two-way (with the medial axis term)",
    "cameras": "the cameras whose images were used, in the order of the per-view lists",
    "frames_with_dropped_targets": "per TRC frame, the targets absent from it (missing, or dropped as outliers)",
    "frames_with_disabled_views": "per TRC frame, the cameras whose silhouette was empty (their view left out)",
    "frames_with_outlier_targets": "per TRC frame, the targets dropped because they lay metres from the body",
    "trc_axes": "the axis convention the TRC files were read and written in, and the evidence",
    "trc_axes.used": "y-up (Pose2Sim, OpenSim) or z-up (the calibration's world)",
    "trc_axes.how": ("detected (against the cameras), forced (--trc-axes), default (no calibration: y-up) or "
                     "triangulated (the targets were triangulated from --videos, in the model's Y-up frame) or "
                     "declared by the C3D file (its POINT:Y_SCREEN, the axis drawn upward)"),
    "trc_axes.decided_by": "when detected, what told the conventions apart: silhouettes, images or upright body",
    "trc_axes.description": "the convention in words, and which outputs are written in it",
    "trc_axes.sampled_frames": "the TRC frame numbers the evidence was measured on",
    "solver_levels": "per level of the priority stack, what it got at each frame (solver_levels.* entries)",
    "solver_levels.stack": "where the stack came from: default, or the stack file",
    "solver_levels.levels": "the stack's levels, highest priority first",
    "trial_lengths": "null unless --trial-lengths reach or images; otherwise the trial_lengths.* entries",
    "trial_lengths.segments_mm": ("mm: per limb segment, its static (calibrated) length, its trial length and the "
                                  "change; reach only ever lengthens a limb, to reach its targets; images may "
                                  "shorten a leg"),
    "trial_lengths.evidence": ("per limb, what decided: the reach (98th percentile of the root-to-end distance over "
                               "3-frame averages) [m], the segments' sum [m] and the factor; or the images (frames, "
                               "the factors chosen, the gain over the calibrated lengths)"),
    "target_filter": ("how the targets were low-passed over time (--target-filter; zero-lag 4th-order Butterworth): "
                      "the target_filter.* entries"),
    "target_filter.mode": "off, auto (each keypoint's cutoff from the trial's residual analysis) or fixed (one cutoff)",
    "target_filter.frame_rate_hz": "Hz: the targets' frame rate the filter used",
    "target_filter.median_cutoff_hz": "Hz: the median of the keypoints' cutoffs (null when off)",
    "target_filter.median_change_rms_mm": "mm: the median over keypoints of the rms distance the filter moved them",
    "target_filter.keypoints": ("per keypoint: cutoff_hz (null: too few valid frames, left as is), noise_mm (the "
                                "residual analysis's noise rms per coordinate; null for a fixed cutoff), "
                                "change_rms_mm and change_max_mm (how far the filter moved it), leap_frames (frames "
                                "kept as they were: farther from their 5-frame median than 10 m/s moves in a frame)"),
    "target_filter.unfiltered_because": ("null, or why auto left every target as it was (a frame rate too low to "
                                         "tell noise from motion above 6 Hz)"),
    "swivel_smoothing": ("how the free elbows' and knees' swivels were low-passed over the trial once every frame "
                         "was solved (--swivel-cutoff; each joint kept on its circle about its limb's ends): the "
                         "swivel_smoothing.* entries; null when it did not run (no image, or off)"),
    "swivel_smoothing.cutoff_hz": "Hz: the cutoff of the zero-lag low-pass",
    "swivel_smoothing.frame_rate_hz": "Hz: the frames' rate it was designed at",
    "swivel_smoothing.applied": "false when the cutoff lies above what the frame rate allows (swivel_smoothing.why)",
    "swivel_smoothing.frames_moved": "frames in which at least one joint moved (farther than 0.5 mm from its place)",
    "swivel_smoothing.joints": ("per free elbow and knee, moved_mm (how far it moved; median and max over the frames "
                                "it was free) and off_smoothed_mm (how far it ended from its smoothed place: the "
                                "targets and joint limits come first)"),
    "warnings": "every warning the run gave on stderr (IbikWarning), in order, each once",
    "kept_user_files": ("paths in OUTDIR that an earlier output held and ibik did not write (not in its manifest): "
                        "kept beside the new outputs; empty folders end with /"),
    "diagnosis": ("what the run judged of its own evidence (app.diagnosis; docs/method.md, Self-diagnosis): the "
                  "diagnosis.* entries"),
    "diagnosis.findings": ("every suspect view or frame: cause (view_targets_outside, view_empty, "
                           "view_mostly_foreground, axes_body_lying, "
                           "view_skeleton_outside, frame_jump, frame_step, frame_residual), subject (camera name or "
                           "TRC frame number), figure and threshold (in the unit of the cause's threshold in "
                           "diagnosis.thresholds; 0-1 shares for views), consequence (what the run did)"),
    "diagnosis.targets_inside_sampled": ("0-1: per camera, before the solve, the share of the projected targets "
                                         "inside its silhouette, median over the sampled frames (null: every "
                                         "sampled silhouette empty)"),
    "diagnosis.sampled_frames": "the TRC frame numbers targets_inside_sampled was measured on",
    "diagnosis.foreground_sampled": ("0-1: per camera, before the solve, the share of the image its silhouette "
                                     "covers, median over the sampled frames"),
    "diagnosis.views_left_out": ("the cameras left out of the image term (their silhouettes taken as empty) because "
                                 "their targets' share was too low; listed in frames_with_disabled_views too"),
    "diagnosis.skeleton_inside_median": ("0-1: per camera, after the solve, the median over the frames of "
                                         "inside_fraction_per_view"),
    "diagnosis.departure_per_frame_m": ("m: per frame, the median over its targets of the distance to where the "
                                        "frames on either side put them (interpolated in time; extrapolated at "
                                        "the ends); null where not measured"),
    "diagnosis.thresholds": ("view_floor, view_ratio and max_foreground (0-1 shares), jump_distance_m [m], "
                             "frame_residual_floor_m "
                             "[m] and frame_residual_ratio (times the trial's median residual)"),
    "method": "the solver scheme: qp, stack, liegeois or ik",
    "qp_solver": "the backend that solved the qp scheme's level QPs (null for the other schemes)",
    "joint_limit_hits": "per TRC frame, the joints (Pinocchio joint names) at a position limit at the solution",
    "solver_levels.status_per_frame": "per level, the solver's status at each frame's last step: " + "; ".join(
        f"{status.value}: {status.definition}" for status in LevelStatus),
    "solver_levels.frames_per_status": "per level, the count of frames that ended in each status",
    "solver_levels.residual_per_frame": ("per level, sqrt(sum of w |e|^2) over its least-squares tasks at each "
                                         "frame's solution: m for position and centre-of-mass tasks, rad for "
                                         "posture; null for the image level"),
    "solver_levels.sacrificed_per_frame": ("per level, the part of its residual the levels above keep it from "
                                           "removing (its residual's unit); for the image level, the share 0-1 of "
                                           "its gradient they take"),
    "solver_levels.criterion_per_frame": "px: per image level, the criterion h(q) at each frame's solution",
    "solver_levels.mean_residual": "the mean of residual_per_frame, in its unit",
    "solver_levels.mean_sacrificed": "the mean of sacrificed_per_frame, in its unit",
}
