"""The paper's virtual experiments (Figs. 6-8) as acceptance tests of the image criterion."""

import numpy as np
import pytest
from paper.virtual_scenes import PAPER_EXPERIMENTS, run_paper_experiment

SCHEMES = ["liegeois", "stack", "qp"]


def test_fig7_ik_leaves_the_internal_joints_where_they_started():
    experiment = PAPER_EXPERIMENTS["fig7"]
    scene, ik = run_paper_experiment("fig7", use_image=False, solver_name="ik")
    assert ik.end_effector_error <= 1e-3
    start = scene.keypoint_positions(experiment.start())
    final = scene.keypoint_positions(ik.trajectory[-1])
    assert np.max(np.linalg.norm(final - start, axis=1)) < 1e-6
    assert ik.internal_joint_error > 0.1


@pytest.mark.parametrize("scheme", SCHEMES)
def test_fig7_the_image_level_brings_the_internal_joints_to_the_objective_in_every_scheme(scheme):
    _, ibik = run_paper_experiment("fig7", use_image=True, solver_name=scheme)
    assert ibik.internal_joint_error <= 0.03
    assert ibik.end_effector_error <= 1e-3


def test_fig6_ibik_internal_joint_error_is_at_least_five_times_lower_than_ik():
    _, ik = run_paper_experiment("fig6", use_image=False, solver_name="ik")
    _, ibik = run_paper_experiment("fig6", use_image=True, solver_name="liegeois")
    assert ibik.internal_joint_error * 5 <= ik.internal_joint_error
    assert ibik.end_effector_error <= 1e-3 and ik.end_effector_error <= 1e-3


def test_fig8_ik_hits_the_object_and_ibik_avoids_it_and_reaches_the_target():
    _, ik = run_paper_experiment("fig8", use_image=False, solver_name="ik")
    assert ik.object_hits > 0
    for scheme in SCHEMES:
        _, ibik = run_paper_experiment("fig8", use_image=True, solver_name=scheme)
        assert ibik.object_hits == 0, scheme
        assert ibik.end_effector_error <= 1e-3, scheme


def test_the_image_level_raises_the_overlap():
    _, ik = run_paper_experiment("fig6", use_image=False, solver_name="ik")
    _, ibik = run_paper_experiment("fig6", use_image=True, solver_name="qp")
    assert ibik.overlap > ik.overlap
