"""The step-budget experiment's variants change only what they name, and its summary pairs each
condition against the reference variant."""

import pytest
from step_budget import VARIANTS, posture_stack, summarize

from ibik_pin.tracking.stack import Stack


def _postures(stack: Stack) -> list:
    return [task for level in stack.levels for task in level.tasks if task.kind == "posture"]


def test_a_posture_variant_changes_the_posture_task_alone():
    default = Stack.default()
    previous = posture_stack(reference="previous")
    assert [task.reference for task in _postures(default)] == ["neutral"]
    assert [task.reference for task in _postures(previous)] == ["previous"]
    assert [(level.name, [task.kind for task in level.tasks]) for level in previous.levels] == \
        [(level.name, [task.kind for task in level.tasks]) for level in default.levels]
    weaker = VARIANTS["posture_gain_0.1"]()["stack"]
    assert [task.gain for task in _postures(weaker)] == [0.1]
    assert [task.reference for task in _postures(weaker)] == ["neutral"]


def test_the_summary_pairs_every_condition_against_the_first_variant():
    rows = [{"index": i, "motion": "m",
             "base": {"elbows": 10.0 + i, "knees": 20.0, "steps_per_frame": 14.0},
             "fewer": {"elbows": 10.0 + i + (2.0 if i == 0 else -0.5), "knees": 18.5, "steps_per_frame": 10.0}}
            for i in range(4)]
    summary = summarize(rows, ["base", "fewer"])
    assert summary["base"]["elbows"]["change_median"] == 0.0
    fewer = summary["fewer"]
    assert fewer["steps_per_frame"] == pytest.approx(10.0)
    assert fewer["elbows"]["change_mean"] == pytest.approx((2.0 - 1.5) / 4)
    assert (fewer["elbows"]["worse"], fewer["elbows"]["better"], fewer["elbows"]["largest_worse"]) == (1, 0, 2.0)
    assert (fewer["knees"]["better"], fewer["knees"]["median"]) == (4, 18.5)
