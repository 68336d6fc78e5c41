"""The paper's virtual experiments (Figs. 6-8) run on the planar chain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ibik_pin.configuration import Configuration
from ibik_pin.model import load_planar_chain
from ibik_pin.solvers import DampedLeastSquaresSolver, Solver, make_solver
from ibik_pin.synthetic.planar import CHAIN_LENGTH, PlanarScene, make_scene
from ibik_pin.tasks import FramePositionTask, ImageTask, View


@dataclass
class PlanarRun:
    """One run of the chain: the configuration at every iteration and the metrics of the paper.

    Errors are fractions of the chain's total length; `object_hits` counts the iterations in which
    a segment crosses the object.
    """

    trajectory: np.ndarray  # (iterations + 1, 4) [rad], the start included
    end_effector_error: float
    internal_joint_error: float
    overlap: float
    object_hits: int



def segment_hits_object(scene: PlanarScene, q: np.ndarray, samples: int = 60) -> bool:
    """Whether any segment of the chain at q crosses the object in the image."""
    if scene.object_mask is None:
        return False
    ends = scene.keypoint_positions(q)
    s = np.linspace(0.0, 1.0, samples)[None, :, None]
    points = ((1 - s) * ends[:-1, None, :] + s * ends[1:, None, :]).reshape(-1, 3)
    pixels = np.rint(scene.camera.project(points)).astype(int)
    height, width = scene.object_mask.shape
    inside = (pixels[:, 0] >= 0) & (pixels[:, 0] < width) & (pixels[:, 1] >= 0) & (pixels[:, 1] < height)
    return bool(scene.object_mask[pixels[inside, 1], pixels[inside, 0]].any())



def run_planar(
    scene: PlanarScene,
    start_q: np.ndarray,
    solver: Solver,
    use_image: bool,
    iterations: int = 400,
    end_effector_gain: float = 1.0,
    image_step: float = 0.05,
    target: np.ndarray | None = None,
) -> PlanarRun:
    """Drive the end effector to the objective's (or `target`), with or without the image level.

    Levels: [end-effector position], then [image criterion] when `use_image`. Every iteration is
    one solver step, recorded.
    """
    body = scene.body
    model = body.model
    objective = scene.keypoint_positions(scene.objective_q)
    goal = objective[-1] if target is None else np.asarray(target, dtype=float)
    end_effector = FramePositionTask(model, body.keypoints["end_effector"], goal, gain=end_effector_gain)
    levels: list[list] = [[end_effector]]
    image_task = ImageTask(body, [View(scene.camera, scene.support)], samples_per_segment=10,
                           max_step_size=image_step)
    if use_image:
        levels.append([image_task])
    configuration = Configuration(model, start_q)
    trajectory = [configuration.q.copy()]
    hits = int(segment_hits_object(scene, configuration.q))
    solver.step_adaptation.reset()
    for _ in range(iterations):
        step = solver.compute_step(configuration, levels)
        configuration.move(step.dq, solver.limits)
        trajectory.append(configuration.q.copy())
        hits += segment_hits_object(scene, configuration.q)
    final = scene.keypoint_positions(configuration.q)
    return PlanarRun(
        trajectory=np.array(trajectory),
        end_effector_error=float(np.linalg.norm(final[-1] - goal) / CHAIN_LENGTH),
        internal_joint_error=float(
            np.mean(np.linalg.norm(final[1:-1] - objective[1:-1], axis=1)) / CHAIN_LENGTH
        ),
        overlap=float(image_task.compute_value(configuration)),
        object_hits=hits,
    )



def same_end_effector_configuration(
    objective_q: np.ndarray, start_q: np.ndarray, iterations: int = 200
) -> np.ndarray:
    """A configuration near `start_q` whose end effector is the objective's (fig7's start)."""
    body = load_planar_chain()
    goal = Configuration(body.model, objective_q).frame_position(body.frame_id("end_effector")).copy()
    task = FramePositionTask(body.model, "end_effector", goal)
    configuration = Configuration(body.model, start_q)
    DampedLeastSquaresSolver(damping=1e-4).solve(configuration, [[task]], iterations=iterations)
    return pin.normalize(body.model, configuration.q)



@dataclass(frozen=True)
class PaperExperiment:
    """One of the paper's virtual experiments and the settings that reproduce it.

    Attributes:
        name: "fig6", "fig7" or "fig8".
        description: what it shows.
        objective_q: the configuration whose silhouette is the image [rad] (fig8: none drawn).
        start_q: where the chain starts [rad]; fig7 derives it (same end effector as the objective).
        target: the end-effector target [m] (None: the objective's end effector).
        obstacle_center: fig8's square object [m], or None.
        end_effector_gain, image_step, iterations: solver settings.
    """

    name: str
    description: str
    objective_q: tuple[float, ...]
    start_q: tuple[float, ...]
    target: tuple[float, float, float] | None = None
    obstacle_center: tuple[float, float, float] | None = None
    end_effector_gain: float = 1.0
    image_step: float = 0.05
    iterations: int = 400

    def scene(self) -> PlanarScene:
        if self.obstacle_center is not None:
            return make_scene(
                np.array(self.objective_q), with_silhouette=False,
                obstacle_center=np.array(self.obstacle_center), obstacle_influence_px=40.0,
            )
        return make_scene(np.array(self.objective_q))

    def start(self) -> np.ndarray:
        if self.name == "fig7":
            return same_end_effector_configuration(np.array(self.objective_q), np.array(self.start_q))
        return np.array(self.start_q)



PAPER_EXPERIMENTS = {
    "fig6": PaperExperiment(
        "fig6", "different start and objective configurations",
        objective_q=(1.2, -0.9, 0.8, -0.6), start_q=(0.3, 0.3, 0.3, 0.3),
    ),
    "fig7": PaperExperiment(
        "fig7", "same end-effector position, different internal configuration",
        objective_q=(0.9, -0.7, -0.6, 0.5), start_q=(-0.2, 0.9, 0.6, -0.6),
    ),
    "fig8": PaperExperiment(
        "fig8", "reach the end-effector target while avoiding a square object drawn into the image",
        objective_q=(0.0, 0.0, 0.0, 0.0), start_q=(-0.6, 0.4, 0.4, 0.4), target=(0.5, 0.7, 0.0),
        obstacle_center=(0.35, 0.3, 0.0), end_effector_gain=0.3, image_step=0.05,
    ),
}



def run_paper_experiment(name: str, use_image: bool, solver_name: str = "stack") -> tuple[PlanarScene, PlanarRun]:
    """Run one of PAPER_EXPERIMENTS as IK (use_image False) or IBIK with the named solver scheme."""
    experiment = PAPER_EXPERIMENTS[name]
    scene = experiment.scene()
    run = run_planar(
        scene, experiment.start(), make_solver(solver_name), use_image,
        iterations=experiment.iterations, end_effector_gain=experiment.end_effector_gain,
        image_step=experiment.image_step,
        target=None if experiment.target is None else np.array(experiment.target),
    )
    return scene, run
