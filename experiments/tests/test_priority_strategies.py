"""The strategies of experiments/priority_strategies.py are valid stacks with the intended shapes."""

from __future__ import annotations

import priority_strategies as experiment

from ibik_pin.human import load_human
from ibik_pin.tracking.stack import Stack


def test_every_strategy_s_stack_is_a_valid_stack_of_the_intended_shape():
    human = load_human()
    stacks = {name: Stack.from_dict(document, source=name) for name, document in experiment._stacks().items()}
    for stack in stacks.values():
        stack.check_names(human.keypoints)
    assert [level.name for level in stacks["liegeois"].levels] == ["end effectors", "image"]
    assert [level.name for level in stacks["image_above_arms"].levels][1] == "image"
    for weight in experiment.IMAGE_WEIGHTS:
        weighted = stacks[f"weighted_w{weight:g}"]
        assert not any(level.strict for level in weighted.levels)  # one QP level
        assert weighted.image is not None and weighted.image.weight == weight
    used = {strategy.stack for strategy in experiment.STRATEGIES} - {None}
    assert used == set(stacks)
