"""The paper's Section 4 evaluation on real motion: IK, PIK and IBIK with 1, 2 and 4 views.

A real clip (CMU walking, CMU BVH, the boxing BVH) is turned into Pose2Sim keypoints, the human
model is scaled to the subject and posed to them (the truth), and its silhouettes are rendered into
HumanEva-like cameras, clean or with realistic defects. Then:

- chain experiments (the paper's Table 1): the arm (shoulder and elbow, 3 DOF each; end effector
  the wrist) on boxing, the leg (hip and knee; end effector the ankle) on walking. The chain's base
  is placed on the true shoulder (hip) joint frame every frame and its segment lengths are the
  subject's; the silhouettes are the whole body's, as in real images.
- whole body (the paper's Table 2): every keypoint but the elbows and knees is a target, solved by
  the same Tracker as `ibik track`.

Methods: "ik" (eq. 3, blind), "pik" (the priority stack without the image level), "ibik" (the image
level under a scheme: "liegeois", "stack" or "qp"). Errors are eq. (9): per frame, the distance of
the estimated internal joint to the true one.
"""

from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ibik_pin.configuration import Configuration
from ibik_pin.evaluation import ESTIMATED
from ibik_pin.exceptions import EmptySilhouetteWarning
from ibik_pin.human import load_human
from ibik_pin.io.asf_amc import read_asf_amc
from ibik_pin.io.bvh import CMU_BVH_SCALE, read_bvh
from ibik_pin.io.skeleton import SkeletonMotion
from ibik_pin.limits import JointLimits
from ibik_pin.model import BodyModel, load_arm, load_leg, set_segment_length
from ibik_pin.readahead.frame_images import frame_images
from ibik_pin.readahead.frames_ahead import FrameImagesAhead
from ibik_pin.solvers import make_solver
from ibik_pin.subject.scaling import scale_human, segment_lengths_from_keypoints
from ibik_pin.synthetic.defects import SilhouetteDefects, apply_defects
from ibik_pin.synthetic.mocap import (
    facing_directions,
    keypoints_from_motion,
    pose_model_to_keypoints,
)
from ibik_pin.synthetic.rig import humaneva_rig
from ibik_pin.synthetic.silhouettes import render_limb_masks, render_silhouettes
from ibik_pin.tasks import FramePositionTask, ImageTask
from ibik_pin.tracking.first_frame import solve_first_frame
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.tracker import Tracker
from ibik_pin.tracking.views import support_caps, target_boxes
from ibik_pin.vision.segmentation import TemporalMajority

# Moderate segmentation defects at HumanEva's 640 x 480: a mask 1 px tight or 2 px loose, a small
# hole, two shadow or clutter blobs, a forearm or shank lost in 5% of the masks. (Holes of 3 px
# and more in 4-7 px wide limbs cut them; with one view the knee then flips to its mirror pose.)
DEFECTS = SilhouetteDefects(erode_px=1, dilate_px=2, holes=1, hole_radius_px=2.0, blobs=2,
                            blob_radius_px=10.0, missing_limb_probability=0.05)
DEFECT_TARGET_NOISE_MM = 5.0
# With defects, IBIK reads the masks as `ibik track --mask-filter 1` does: each pixel voted over 3
# frames, which removes the one-frame holes, blobs and lost limbs above (not the erosion/dilation).
DEFECT_MASK_FILTER_RADIUS = 1


@dataclass
class Clip:
    """A real motion posed on the scaled human: the truth of every experiment on it.

    Attributes:
        name: the clip's name.
        body: the human scaled to the subject.
        q: (F, nq) the true configurations.
        keypoint_names: the body's keypoints; keypoints: (F, K, 3) their true positions [m].
        target_names: the keypoints the source measures (the others are the model's own).
        frame_rate: [Hz].
        fit_residual: (F,) mean distance of the posed model to the source keypoints [m].
    """

    name: str
    body: BodyModel
    q: np.ndarray
    keypoint_names: list[str]
    keypoints: np.ndarray
    target_names: list[str]
    frame_rate: float
    fit_residual: np.ndarray

    def keypoint(self, name: str) -> np.ndarray:
        """(F, 3) true positions of one keypoint [m]."""
        return self.keypoints[:, self.keypoint_names.index(name)]


def load_motion(path: Path, source: str, asf: Path | None = None) -> SkeletonMotion:
    """A real clip: "asf" (with its .asf), "cmu_bvh" or "boxing" (the BVH in centimetres)."""
    if source == "asf":
        return read_asf_amc(asf, path)
    scale = CMU_BVH_SCALE if source == "cmu_bvh" else 0.01
    return read_bvh(path, scale=scale).to_skeleton_motion()


def prepare_clip(name: str, motion: SkeletonMotion, source: str, frames: slice) -> Clip:
    """Scale the human to the subject and pose it to the frames of the motion."""
    motion = motion.subset(frames)
    names, positions = keypoints_from_motion(motion, source)
    body = scale_human(load_human(), segment_lengths_from_keypoints(names, positions))
    q, residual = pose_model_to_keypoints(body, names, positions)
    keypoint_names = list(body.keypoints)
    ids = body.frame_ids(keypoint_names)
    configuration = Configuration(body.model)
    keypoints = np.empty((len(q), len(ids), 3))
    for frame, q_frame in enumerate(q):
        configuration.update(q_frame)
        keypoints[frame] = configuration.frame_positions(ids)
    return Clip(name, body, q, keypoint_names, keypoints, list(names), motion.frame_rate, residual)


@dataclass
class Views:
    """Cameras and the silhouettes of every frame in each (clean or with defects)."""

    cameras: list
    masks: list[list[np.ndarray]]  # [frame][camera] (H, W) bool


def render_views(clip: Clip, count: int, defects: SilhouetteDefects | None = None, seed: int = 0) -> Views:
    """`count` HumanEva-like cameras around the clip and its silhouettes in them.

    The cameras are ordered from the most frontal to the least (the subject's mean facing), so
    that the 1- and 2-view subsets are the front camera(s), as a capture set-up places them; with
    4 evenly spread cameras the first two see the subject front-left and front-right.
    """
    center = np.nanmean(clip.keypoint("Hip"), axis=0)
    cameras = humaneva_rig(count, center, seed=seed)
    facing = np.nanmean(facing_directions(clip.keypoint_names, clip.keypoints), axis=0)
    frontal = [float(facing @ (camera.center_world - center) / np.linalg.norm(camera.center_world - center))
               for camera in cameras]
    cameras = [cameras[index] for index in np.argsort(frontal)[::-1]]
    rng = np.random.default_rng(seed)
    masks = []
    for q in clip.q:
        frame_masks = render_silhouettes(clip.body, q, cameras)
        if defects is not None:
            frame_masks = [apply_defects(mask, defects, rng, render_limb_masks(clip.body, q, camera))
                           for mask, camera in zip(frame_masks, cameras, strict=True)]
        masks.append(frame_masks)
    return Views(cameras, masks)


def temporally_filtered(views: Views, radius: int) -> Views:
    """The same cameras with every camera's masks voted over 2 radius + 1 frames (TemporalMajority)."""
    vote = TemporalMajority(lambda frame: views.masks[frame], len(views.masks), radius)
    return Views(views.cameras, [vote(frame) for frame in range(len(views.masks))])


def subset_views(views: Views, count: int) -> Views:
    """The first `count` cameras of a rig (1, 2 and 4 views share cameras)."""
    return Views(views.cameras[:count], [frame[:count] for frame in views.masks])




@dataclass
class Run:
    """One method on one clip: per-frame errors of the estimated joints and the positions found.

    Attributes:
        joints: the estimated (internal) joints; errors: (F, J) their eq. (9) distances [m].
        positions: the chain's or the body's keypoint positions per frame [m].
        tracked_seconds: the time the frames after the first took, each solved from the one before
            (the paper's setting; the first frame's search from the neutral pose is not counted);
            NaN where not measured.
    """

    joints: list[str]
    errors: np.ndarray
    positions: np.ndarray
    tracked_seconds: float = float("nan")

    @property
    def mean_error_mm(self) -> float:
        return float(np.mean(self.errors) * 1000.0)


@dataclass(frozen=True)
class Chain:
    """One of the paper's 3D chains on the human: its keypoints and where its base sits."""

    name: str
    base: str  # the human joint whose (unrotated) frame is the chain's base
    root: str  # keypoint names: base, internal joint, end effector
    internal: str
    end: str


CHAINS = {
    "arm": Chain("arm", "right_shoulder_Z", "RShoulder", "RElbow", "RWrist"),
    "leg": Chain("leg", "right_hip_Z", "RHip", "RKnee", "RAnkle"),
}


def _chain_body(chain: Chain, clip: Clip) -> BodyModel:
    """The arm or leg model with the subject's two segment lengths."""
    body = load_arm() if chain.name == "arm" else load_leg()
    model = body.model
    first = float(np.median(np.linalg.norm(clip.keypoint(chain.internal) - clip.keypoint(chain.root), axis=1)))
    second = float(np.median(np.linalg.norm(clip.keypoint(chain.end) - clip.keypoint(chain.internal), axis=1)))
    set_segment_length(model, "elbow_Z" if chain.name == "arm" else "knee_Z", first)
    end_frame = model.frames[model.getFrameId("wrist" if chain.name == "arm" else "ankle")]
    end_frame.placement.translation = end_frame.placement.translation * (
        second / np.linalg.norm(end_frame.placement.translation))
    return body


def _base_placements(chain: Chain, clip: Clip) -> list[pin.SE3]:
    """Per frame, the world placement of the human's base joint before its own rotation."""
    model = clip.body.model
    data = model.createData()
    joint = model.getJointId(chain.base)
    parent = model.parents[joint]
    placements = []
    for q in clip.q:
        pin.forwardKinematics(model, data, q)
        placements.append(data.oMi[parent] * model.jointPlacements[joint])
    return placements


def run_chain(
    chain_name: str,
    clip: Clip,
    views: Views | None,
    method: str,
    scheme: str = "liegeois",
    iterations: int = 15,
    target_noise_mm: float = 0.0,
    seed: int = 0,
    image_step: float = 0.05,
) -> Run:
    """Track the chain's internal joint through the clip.

    Args:
        method: "ik", "pik" or "ibik" (needs views).
        scheme: the solver scheme of "ibik".
        target_noise_mm: Gaussian noise per axis on the end-effector target [mm].
        image_step: largest image step per iteration [rad].

    Returns:
        errors (F, 1) of the internal joint [m]; positions (F, 3, 3) of base, internal joint and
        end effector [m].
    """
    chain = CHAINS[chain_name]
    body = _chain_body(chain, clip)
    model = body.model
    solver_name = {"ik": "ik", "pik": "stack"}.get(method, scheme)
    solver = make_solver(solver_name, limits=JointLimits(model))
    rng = np.random.default_rng(seed)
    targets = clip.keypoint(chain.end) + rng.normal(0.0, target_noise_mm / 1000.0, (len(clip.q), 3))
    end_task = FramePositionTask(model, body.keypoints["Wrist" if chain.name == "arm" else "Ankle"])
    levels: list[list] = [[end_task]]
    image_task, prepare = None, None
    if method == "ibik":
        image_task = ImageTask(body, (), samples_per_segment=8, max_step_size=image_step)
        levels.append([image_task])
        caps = support_caps(views.cameras, clip.keypoint("Hip")[0])
        # As `ibik track`: each frame's support images built ahead (by default in a child process),
        # their windows covering the known points (the chain's base and its end's target).
        known = np.stack([clip.keypoint(chain.root), targets], axis=1)
        prepare = functools.partial(frame_images, views.masks.__getitem__, views.cameras, caps, None,
                                    target_boxes=target_boxes(views.cameras, known))
    chain_ids = body.frame_ids(list(body.keypoints))  # base, internal joint, end effector
    placements = _base_placements(chain, clip)
    configuration = Configuration(model)
    positions = np.empty((len(clip.q), 3, 3))
    tracked_from = float("nan")
    with FrameImagesAhead(prepare, len(clip.q)) as images:
        for frame in range(len(clip.q)):
            if frame == 1:
                tracked_from = time.perf_counter()
            model.jointPlacements[1] = placements[frame]
            configuration.update()
            end_task.set_target(targets[frame])
            if image_task is not None:
                with warnings.catch_warnings():  # an empty view is simply skipped
                    warnings.simplefilter("ignore", EmptySilhouetteWarning)
                    image_task.set_views(images.get(frame).views)
            # The first frame searched from several starts, as `ibik track` does; its image solves run
            # their 100 steps here, where ibik track's stop at the criterion's peak (docs/method.md).
            if frame == 0:
                solve_first_frame(solver, configuration, levels, image_task, iterations=100, starts=8)
            else:
                solver.solve(configuration, levels, iterations=iterations)
            positions[frame] = configuration.frame_positions(chain_ids)
    tracked_seconds = time.perf_counter() - tracked_from
    errors = np.linalg.norm(positions[:, 1] - clip.keypoint(chain.internal), axis=1)
    return Run([chain.internal], errors[:, None], positions, tracked_seconds)


def run_full_body(
    clip: Clip,
    views: Views | None,
    method: str,
    scheme: str = "qp",
    iterations: int = 15,
    target_noise_mm: float = 0.0,
    seed: int = 0,
) -> Run:
    """Track the whole body from every measured keypoint but the elbows and knees.

    Returns:
        errors (F, 4) of LElbow, RElbow, LKnee, RKnee [m]; positions (F, K, 3) of every keypoint.
    """
    names = [name for name in clip.target_names if name not in ESTIMATED]
    indices = [clip.keypoint_names.index(name) for name in names]
    rng = np.random.default_rng(seed)
    targets = clip.keypoints[:, indices] + rng.normal(0.0, target_noise_mm / 1000.0, (len(clip.q), len(names), 3))
    use_image = method == "ibik"
    solver_name = {"ik": "ik", "pik": "stack"}.get(method, scheme)
    # The paper's method as published: its criterion, no swivel search, every target an end effector,
    # its fixed count of steps per frame.
    settings = TrackingSettings(method=solver_name, iterations=iterations, use_image=use_image,
                                criterion="paper", swivel_search=False, feet_by_ankle=False,
                                image_moves="all", image_stop="count")
    tracker = Tracker(clip.body, views.cameras if (use_image and views) else [], settings)
    result = tracker.track(names, targets, (lambda frame: views.masks[frame]) if use_image else None)
    estimated = [result.keypoint_names.index(name) for name in ESTIMATED]
    truth = [clip.keypoint_names.index(name) for name in ESTIMATED]
    errors = np.linalg.norm(result.keypoints[:, estimated] - clip.keypoints[:, truth], axis=2)
    return Run(list(ESTIMATED), errors, result.keypoints)
