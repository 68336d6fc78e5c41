"""The outcome of one priority level at one step: :class:`LevelStatus`."""

from __future__ import annotations

from enum import Enum

__all__ = ["LevelStatus"]

_DEFINITIONS = {
    "solved": "The level's optimum reaches its target: the residual |A dq - b| is at most 1e-6 plus 5% of "
              "|b| (the part damping alone leaves), or a gradient level took a step of nonzero norm.",
    "relaxed": "Not a failure: the level's least-squares optimum under the higher levels and the joint "
               "limits, which leaves a residual (reported in LevelReport.residual) because those forbid "
               "reaching its target exactly.",
    "failed": "The QP backend returned no answer for the level (its own status is in "
              "LevelReport.detail); the level took no step and its null space went to the levels below.",
    "empty": "Nothing to do: no enabled task, no null space left by the higher levels, or a zero gradient.",
}


class LevelStatus(str, Enum):
    """What a level got at a step (LevelReport.status).

    A `str`-valued Enum: a member equals its value ("solved" == LevelStatus.SOLVED), formats as it and
    is written to JSON as it. `definition` gives each member's meaning in one sentence.
    """

    SOLVED = "solved"
    RELAXED = "relaxed"
    FAILED = "failed"
    EMPTY = "empty"

    def __str__(self) -> str:  # the value, as format() and f-strings show it, on every Python
        return self.value

    def __format__(self, format_spec: str) -> str:
        return format(self.value, format_spec)

    @property
    def definition(self) -> str:
        """One sentence saying what the status means."""
        return _DEFINITIONS[self.value]
