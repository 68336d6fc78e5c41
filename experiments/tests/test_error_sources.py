"""The error-sources diagnosis makes exactly the part of a limb's lengths true that it names."""

import pytest
from error_sources import with_true_parts

CHOSEN = {"left_thigh": 0.41, "left_shank": 0.44, "right_thigh": 0.43, "right_shank": 0.40,
          "left_upper_arm": 0.30, "left_forearm": 0.27, "right_upper_arm": 0.29, "right_forearm": 0.28}
TRUE = {"left_thigh": 0.42, "left_shank": 0.41, "right_thigh": 0.40, "right_shank": 0.42,
        "left_upper_arm": 0.31, "left_forearm": 0.26, "right_upper_arm": 0.30, "right_forearm": 0.27}


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_true_sum_keeps_the_chosen_split_and_a_true_split_the_chosen_sum(side):
    thigh, shank = f"{side}_thigh", f"{side}_shank"
    summed = with_true_parts(CHOSEN, TRUE, "leg", "sum")
    assert summed[thigh] + summed[shank] == pytest.approx(TRUE[thigh] + TRUE[shank], abs=1e-12)
    assert summed[thigh] / summed[shank] == pytest.approx(CHOSEN[thigh] / CHOSEN[shank], rel=1e-12)
    split = with_true_parts(CHOSEN, TRUE, "leg", "split")
    assert split[thigh] + split[shank] == pytest.approx(CHOSEN[thigh] + CHOSEN[shank], abs=1e-12)
    assert split[thigh] / split[shank] == pytest.approx(TRUE[thigh] / TRUE[shank], rel=1e-12)
    for arm in ("upper_arm", "forearm"):  # the other limb untouched
        assert summed[f"{side}_{arm}"] == CHOSEN[f"{side}_{arm}"] and split[f"{side}_{arm}"] == CHOSEN[f"{side}_{arm}"]


def test_both_parts_true_give_the_true_lengths_of_that_limb_only():
    arms = with_true_parts(CHOSEN, TRUE, "arm", "both")
    assert all(arms[name] == TRUE[name] for name in TRUE if "arm" in name)
    assert all(arms[name] == CHOSEN[name] for name in CHOSEN if "arm" not in name)
    with pytest.raises(ValueError, match="expected leg or arm"):
        with_true_parts(CHOSEN, TRUE, "neck", "sum")
