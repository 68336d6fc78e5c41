"""Checks of a written report.json shared by the tests of the runs that write one."""

from __future__ import annotations

# Records keyed by targets, cameras or frames rather than by fields: their values are defined as a whole.
KEYED_BY_DATA = ("units", "keypoint_residual_m", "overlap_per_view", "inside_fraction_per_view", "joint_limit_hits")


def undefined_keys(written: dict) -> list[str]:
    """The keys of a written report.json without an entry in its "units": top-level keys, and the keys
    of the records inside (trc_axes, solver_levels, silhouettes, ...) as "record.key"."""
    units = written["units"]
    undefined = [key for key in written if key not in units and key != "units"]
    for record, value in written.items():
        if isinstance(value, dict) and record not in KEYED_BY_DATA and not record.startswith("frames_with_"):
            undefined += [f"{record}.{key}" for key in value if f"{record}.{key}" not in units]
    return undefined
