"""Tests of ibik_pin.tasks.criterion_step: a gradient task as one weighted least-squares row."""

import numpy as np
import pytest

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import InputError
from ibik_pin.solvers import make_solver
from ibik_pin.tasks.base import GradientTask
from ibik_pin.tasks.criterion_step import CriterionStepTask


class Height(GradientTask):
    """h(q) = sum of the planar chain's joint angles weighted by (1, 2, 3, 4): a known gradient."""

    slopes = np.array([1.0, 2.0, 3.0, 4.0])

    def compute_value(self, configuration):
        return float(self.slopes @ configuration.q)

    def compute_gradient(self, configuration):
        return self.slopes.copy()


@pytest.fixture
def chain():
    from ibik_pin.model import load_planar_chain

    return load_planar_chain()


def test_the_row_asks_for_the_step_along_the_unit_gradient(chain):
    row = CriterionStepTask(Height(), step=0.05, weight=4.0)
    A, b = row.compute_linear_system(Configuration(chain.model))
    unit = Height.slopes / np.linalg.norm(Height.slopes)
    np.testing.assert_allclose(A, 2.0 * unit[None, :], atol=1e-15)  # sqrt(weight) g^T
    np.testing.assert_allclose(b, [2.0 * 0.05], atol=1e-15)


def test_alone_in_a_level_the_solver_climbs_by_the_step_each_iteration(chain):
    configuration = Configuration(chain.model)
    solver = make_solver("stack", damping=1e-6)
    solver.solve(configuration, [[CriterionStepTask(Height(), step=0.01)]], iterations=5)
    assert Height().compute_value(configuration) == pytest.approx(5 * 0.01 * np.linalg.norm(Height.slopes), rel=1e-6)


def test_the_row_follows_its_criterion_s_enabled_flag(chain):
    criterion = Height()
    row = CriterionStepTask(criterion, step=0.01)
    assert row.enabled
    criterion.enabled = False
    assert not row.enabled


def test_a_step_that_is_not_positive_is_refused():
    with pytest.raises(InputError, match=r"step must be a positive finite number, got 0\.0"):
        CriterionStepTask(Height(), step=0.0)
