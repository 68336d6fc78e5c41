"""LevelStatus: the level outcomes as a str-valued Enum, each with its definition."""

import json

from ibik_pin.solvers import LevelStatus


def test_level_status_members_equal_and_format_as_their_old_strings():
    for name in ("solved", "relaxed", "failed", "empty"):
        status = LevelStatus(name)
        assert status == name
        assert f"{status}" == name and str(status) == name
        assert json.dumps(status) == json.dumps(name)


def test_every_level_status_has_a_one_sentence_definition():
    for status in LevelStatus:
        assert status.definition.endswith(".") and status.definition.count(". ") == 0


def test_relaxed_is_defined_as_not_a_failure_with_its_residual_reported():
    assert "not a failure" in LevelStatus.RELAXED.definition.lower()
    assert "residual" in LevelStatus.RELAXED.definition
