"""The static fit of subject calibration: its unknowns, its cost, the residuals and their Jacobians.

:class:`StaticFit` holds, on a working copy of the start model, the pose of each static frame,
the placement of each keypoint on its segment and one parameter per joint group
(:mod:`~ibik_pin.subject.calibration_settings`), and evaluates the cost that
:mod:`ibik_pin.subject.calibration` describes. :mod:`~ibik_pin.subject.static_fit_solver`
minimises it.
"""

from __future__ import annotations

import copy
import dataclasses
import warnings

import numpy as np
import pinocchio as pin

from ibik_pin.model import BodyModel
from ibik_pin.subject.calibration_settings import (
    JOINT_CENTRE_KEYPOINTS,
    SCALE_GROUPS,
    SHIFT_GROUPS,
    SHOULDER_KEYPOINTS,
    CalibrationSettings,
)

__all__ = ["StaticFit"]

# Joints whose static angle is taken as the model's neutral one (the reference posture).
_SPINE_JOINT_PREFIXES = ("middle_lumbar", "middle_thoracic")
_CLAVICLE_JOINT_PREFIXES = ("left_clavicle", "right_clavicle")
_NECK_JOINT_PREFIXES = ("middle_cervical",)
# Bounds of a segment scale.
_SCALE_BOUNDS = (0.5, 2.0)


class StaticFit:
    """The static fit on a working copy of the start model: poses (F, nq), keypoint placements
    (K, 3) [m] and one parameter per joint group (G,), and their cost.

    The model unknowns form one vector theta (3K + G,): the placements [m], row by row, then the
    groups' parameters (a scale, or a shift [m]).
    """

    def __init__(self, start: BodyModel, names: list[str], points: np.ndarray, present: np.ndarray,
                 settings: CalibrationSettings) -> None:
        self.start = start
        self.settings = settings
        self.names = names
        self.points = points
        self.present = present
        self.model = copy.deepcopy(start.model)
        self.data = self.model.createData()
        model = self.model
        self.frame_ids = [int(i) for i in start.frame_ids(names)]
        self.anchors = [_attach_to_proximal_segment(model, frame_id) for frame_id in self.frame_ids]
        self.parent_joints = [int(model.frames[i].parentJoint) for i in self.frame_ids]
        self.frame_rotations = [model.frames[i].placement.rotation.copy() for i in self.frame_ids]
        # The unknown of a keypoint: its frame's translation, less its anchor joint's (if any).
        self.offsets_start = np.array([
            model.frames[i].placement.translation - (model.jointPlacements[anchor].translation if anchor else 0.0)
            for i, anchor in zip(self.frame_ids, self.anchors, strict=True)])
        self.offsets = self.offsets_start.copy()
        stiffness = [settings.joint_centre_stiffness if name in JOINT_CENTRE_KEYPOINTS
                     else settings.shoulder_stiffness if name in SHOULDER_KEYPOINTS else 1.0 for name in names]
        self.offset_weights = settings.offset_weight * np.array(stiffness)

        # Joint groups, each one parameter p: translation = start + (p - p_start) * direction. A
        # scale (p_start 1) moves along the start translation, a shift (p_start 0, [m]) along a unit
        # vector; both cost scale_weight per metre the group's joints move.
        self.groups: list[tuple[str, list[tuple[int, np.ndarray]]]] = []
        starts, weights, bounds = [], [], []
        for kind, table in (("scale", SCALE_GROUPS), ("shift", SHIFT_GROUPS)):
            for group, members in table.items():
                entries = [(model.getJointId(joint), np.asarray(axes, dtype=float)) for joint, axes in members
                           if model.existJointName(joint)]
                if kind == "scale":
                    entries = [(joint, axes * model.jointPlacements[joint].translation) for joint, axes in entries]
                entries = [(joint, direction) for joint, direction in entries if np.linalg.norm(direction) > 0.0]
                if not entries:
                    continue
                self.groups.append((group, entries))
                starts.append(1.0 if kind == "scale" else 0.0)
                weights.append(settings.scale_weight * np.sqrt(sum(d @ d for _, d in entries)))
                bounds.append(_SCALE_BOUNDS if kind == "scale" else (-settings.max_shift, settings.max_shift))
        self.group_starts = np.array(starts)
        self.group_weights = np.array(weights)
        self.group_bounds = np.array(bounds).reshape(-1, 2)
        self.scales = self.group_starts.copy()
        self.joint_start = {joint: model.jointPlacements[joint].copy()
                            for _, entries in self.groups for joint, _ in entries}
        # A keypoint moves with a joint's translation when that joint carries its frame, or is its anchor.
        moved_by = [{*model.supports[joint], anchor} for joint, anchor in zip(self.parent_joints, self.anchors,
                                                                              strict=True)]
        self.group_moves = [[(k, joint, direction) for joint, direction in entries
                             for k in range(len(names)) if joint in moved_by[k]]
                            for _, entries in self.groups]

        # For frame_terms, on arrays: each keypoint's velocity columns (the joints carrying its frame),
        # and the groups' moves as (keypoint, group, parent joint of the moved joint, direction) rows.
        self._support = np.zeros((len(names), model.nv), dtype=bool)
        for k, joint in enumerate(self.parent_joints):
            for ancestor in model.supports[joint]:
                if ancestor:
                    self._support[k, model.idx_vs[ancestor]:model.idx_vs[ancestor] + model.nvs[ancestor]] = True
        moves = [(k, g, int(model.parents[joint]), direction) for g, entries in enumerate(self.group_moves)
                 for k, joint, direction in entries]
        self._move_keypoints = np.array([move[0] for move in moves], dtype=int)
        self._move_groups = np.array([move[1] for move in moves], dtype=int)
        self._move_parents, self._move_parent_rows = np.unique(np.array([move[2] for move in moves], dtype=int),
                                                               return_inverse=True)
        self._move_directions = np.array([move[3] for move in moves], dtype=float).reshape(-1, 3)

        # Revolute coordinates: limits and posture weights (the free-flyer is left free).
        revolute = [joint for joint in range(1, model.njoints) if model.nqs[joint] == 1 and model.nvs[joint] == 1]
        self.revolute_q = np.array([model.idx_qs[joint] for joint in revolute], dtype=int)
        self.revolute_v = np.array([model.idx_vs[joint] for joint in revolute], dtype=int)
        posture = [settings.spine_posture_weight if model.names[joint].startswith(_SPINE_JOINT_PREFIXES)
                   else settings.clavicle_posture_weight if model.names[joint].startswith(_CLAVICLE_JOINT_PREFIXES)
                   else settings.neck_posture_weight if model.names[joint].startswith(_NECK_JOINT_PREFIXES)
                   else settings.limb_posture_weight for joint in revolute]
        self.posture_weights = np.array(posture)
        self.lower = model.lowerPositionLimit[self.revolute_q]
        self.upper = model.upperPositionLimit[self.revolute_q]

        self.q = np.array([self._initial_pose(frame) for frame in range(points.shape[0])])

    # --- Model and poses ----------------------------------------------------------------------

    def _initial_pose(self, frame: int) -> np.ndarray:
        """The neutral pose moved rigidly onto the frame's keypoints (best rotation and translation)."""
        model = self.model
        q = pin.neutral(model)
        pin.framesForwardKinematics(model, self.data, q)
        mask = self.present[frame]
        source = np.array([self.data.oMf[i].translation for i in self.frame_ids])[mask]
        target = self.points[frame, mask]
        if model.joints[1].shortname() == "JointModelFreeFlyer":
            rotation, translation = _rigid_fit(source, target)
            q[:7] = pin.SE3ToXYZQUAT(pin.SE3(rotation, translation))
        return q

    def _apply(self, offsets: np.ndarray, scales: np.ndarray) -> None:
        """Set the working model's keypoint frames and joint placements."""
        model = self.model
        translations = {joint: placement.translation.copy() for joint, placement in self.joint_start.items()}
        for (_, entries), value, start in zip(self.groups, scales, self.group_starts, strict=True):
            for joint, direction in entries:
                translations[joint] += (value - start) * direction
        for joint, translation in translations.items():
            model.jointPlacements[joint] = pin.SE3(self.joint_start[joint].rotation, translation)
        for frame_id, rotation, offset, anchor in zip(self.frame_ids, self.frame_rotations, offsets, self.anchors,
                                                      strict=True):
            frame = model.frames[frame_id]
            base = model.jointPlacements[anchor].translation if anchor else 0.0
            frame.placement = pin.SE3(rotation, base + offset)
            model.frames[frame_id] = frame

    def _positions(self, q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array([self.data.oMf[i].translation for i in self.frame_ids])

    def keypoint_residuals(self) -> np.ndarray:
        """Per keypoint, [mean, max] distance over frames where present, shape (K, 2) [m]."""
        self._apply(self.offsets, self.scales)
        distances = np.array([np.linalg.norm(self._positions(q) - target, axis=1)
                              for q, target in zip(self.q, self.points, strict=True)])
        distances[~self.present] = np.nan
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.stack([np.nanmean(distances, axis=0), np.nanmax(distances, axis=0)], axis=1)

    # --- The cost, its residuals and their Jacobians -------------------------------------------

    def model_vector(self) -> np.ndarray:
        """The current model unknowns theta, shape (3K + G,)."""
        return np.concatenate([self.offsets.reshape(-1), self.scales])

    def set_model_vector(self, theta: np.ndarray) -> None:
        """Take theta (3K + G,) as the model unknowns and set the working model to them."""
        count = 3 * len(self.names)
        if np.array_equal(theta, self.model_vector()):  # the model already holds it (the poses-only stage)
            return
        self.offsets = theta[:count].reshape(-1, 3).copy()
        self.scales = theta[count:].copy()
        self._apply(self.offsets, self.scales)

    def model_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of theta, each shape (3K + G,): ``max_offset`` about the start's
        placements, the groups' scale or shift bounds."""
        box = self.settings.max_offset
        lower = np.concatenate([(self.offsets_start - box).reshape(-1), self.group_bounds[:, 0]])
        upper = np.concatenate([(self.offsets_start + box).reshape(-1), self.group_bounds[:, 1]])
        return lower, upper

    def model_prior(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual of the placement and segment priors, and its (diagonal) Jacobian weights."""
        weights = np.concatenate([np.repeat(self.offset_weights, 3), self.group_weights])
        centre = np.concatenate([self.offsets_start.reshape(-1), self.group_starts])
        return weights * (theta - centre), weights

    def frame_terms(self, frame: int, q: np.ndarray, with_model: bool):
        """One frame on the working model at q: data residuals (3K,) (0 where absent), the distance
        weights of the robust loss (K,), d residual / d v (3K, nv) and d residual / d theta
        (3K, 3K + G) or None."""
        model, data = self.model, self.data
        key_count = len(self.names)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        present = self.present[frame]
        positions = np.array([data.oMf[i].translation for i in self.frame_ids])
        residual = positions - self.points[frame]
        residual[~present] = 0.0
        weights = _robust_weights(np.linalg.norm(residual, axis=1), self.settings.robust_scale)
        # Each keypoint's velocity, world-aligned, from the joints' spatial Jacobian (data.J, world
        # frame): v = v_origin + w x p over the columns of the joints that carry it (as
        # getFrameJacobian's LOCAL_WORLD_ALIGNED rows, one call for every keypoint).
        linear, angular = data.J[:3].T, data.J[3:].T  # (nv, 3) each
        w, p = angular[None], positions[:, None]  # w x p by components (np.cross costs more than the rest)
        columns = linear[None] + np.stack([w[..., 1] * p[..., 2] - w[..., 2] * p[..., 1],
                                           w[..., 2] * p[..., 0] - w[..., 0] * p[..., 2],
                                           w[..., 0] * p[..., 1] - w[..., 1] * p[..., 0]], axis=2)  # (K, nv, 3)
        columns *= (self._support & present[:, None])[..., None]
        pose_jacobian = columns.transpose(0, 2, 1).reshape(3 * key_count, model.nv)
        model_jacobian = None
        if with_model:
            observed = np.flatnonzero(present)
            placements = np.zeros((key_count, 3, key_count, 3))
            placements[observed, :, observed, :] = np.array([data.oMi[self.parent_joints[k]].rotation
                                                             for k in observed]).reshape(-1, 3, 3)
            groups = np.zeros((key_count, len(self.groups), 3))
            if self._move_keypoints.size:
                rotations = np.array([data.oMi[int(joint)].rotation for joint in self._move_parents])
                moved = np.matmul(rotations[self._move_parent_rows], self._move_directions[..., None])[..., 0]
                moved[~present[self._move_keypoints]] = 0.0
                np.add.at(groups, (self._move_keypoints, self._move_groups), moved)
            model_jacobian = np.concatenate([placements.reshape(3 * key_count, 3 * key_count),
                                             groups.transpose(0, 2, 1).reshape(3 * key_count, -1)], axis=1)
        return residual.reshape(-1), weights, pose_jacobian, model_jacobian

    def cost(self, q: np.ndarray, theta: np.ndarray | None) -> float:
        """The calibration cost (:mod:`ibik_pin.subject.calibration`) of poses q (F, nq) and theta
        (the current model unknowns if None), with the robust loss on the data term."""
        if theta is not None:
            self.set_model_vector(theta)
        positions = np.array([self._positions(configuration) for configuration in q])  # (F, K, 3)
        distances = np.linalg.norm(positions - self.points, axis=2)[self.present]
        total = float(np.sum(_robust_loss(distances, self.settings.robust_scale)))
        total += float(np.sum((self.posture_weights * q[:, self.revolute_q]) ** 2))
        prior, _ = self.model_prior(self.model_vector() if theta is None else theta)
        return total + float(prior @ prior)

    def clip(self, q: np.ndarray) -> np.ndarray:
        """A copy of the pose q (nq,) with its revolute coordinates inside the joint limits."""
        q = q.copy()
        q[self.revolute_q] = np.clip(q[self.revolute_q], self.lower, self.upper)
        return q

    def calibrated_body(self) -> BodyModel:
        """A copy of the start body with the fitted placements and scales, marked calibrated."""
        self._apply(self.offsets, self.scales)
        return dataclasses.replace(
            self.start,
            model=copy.deepcopy(self.model),
            keypoints=dict(self.start.keypoints),
            segments=list(self.start.segments),
            segment_radii=np.array(self.start.segment_radii, dtype=float),
            end_effectors=list(self.start.end_effectors),
            calibrated=True,
        )


def _attach_to_proximal_segment(model: pin.Model, frame_id: int) -> int:
    """Move a keypoint frame that sits at its joint's origin to the parent joint's frame (same place).

    Such a keypoint (a hip, knee, shoulder, elbow, the Neck) belongs to the proximal segment. Left
    on its joint's own frame, any offset would make its target see that joint's rotation: a hip
    target 1 mm off the hip's axes would hold the hip's flexion at the targets' priority, which
    the image criterion then cannot move. Returns the joint whose origin the keypoint now follows
    (0 if the frame was left where it was: off its joint's origin, or on the root).
    """
    frame = model.frames[frame_id]
    joint = int(frame.parentJoint)
    if joint == 0 or np.linalg.norm(frame.placement.translation) > 1e-12 or \
            model.joints[joint].shortname() == "JointModelFreeFlyer":
        return 0
    parent = int(model.parents[joint])
    frame.placement = model.jointPlacements[joint] * frame.placement
    frame.parentJoint = parent
    frame.parentFrame = model.getFrameId(model.names[parent])
    model.frames[frame_id] = frame
    return joint


def _robust_loss(distances: np.ndarray, scale: float) -> np.ndarray:
    """Huber's loss of distances [m]: d^2 up to `scale`, then linear (2 scale d - scale^2)."""
    if scale <= 0.0:
        return distances**2
    return np.where(distances <= scale, distances**2, 2.0 * scale * distances - scale**2)


def _robust_weights(distances: np.ndarray, scale: float) -> np.ndarray:
    """Iteratively reweighted least squares weights of Huber's loss: 1, or scale / d beyond scale."""
    if scale <= 0.0:
        return np.ones_like(distances)
    return np.minimum(1.0, scale / np.maximum(distances, 1e-12))


def _rigid_fit(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (3, 3) and translation t (3,) minimising |R source + t - target| over the rows."""
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    covariance = (target - target_mean).T @ (source - source_mean)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.sign(np.linalg.det(u @ vt)) or 1.0
    rotation = u @ np.diag([1.0, 1.0, sign]) @ vt
    return rotation, target_mean - rotation @ source_mean
