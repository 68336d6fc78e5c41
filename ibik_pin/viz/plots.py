"""Plots of per-frame series (PNG); matplotlib is imported only when a plot is drawn.

matplotlib takes 0.5-0.7 s to import (measured on the development machine) and only the plots
need it: importing this module, as the tracking pipeline does, must not cost that when no plot is
asked for.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.io.files import write_atomically

__all__ = ["JOINT_ANGLES", "Panel", "joint_angle_panels", "plot_panels", "plot_series"]

# The angles a biomechanist reads first, as motion.mot's columns (degrees; flexion positive, ankle:
# dorsiflexion positive), per panel: (title, left column, right column).
JOINT_ANGLES = (
    ("hip flexion", "left_hip_Z", "right_hip_Z"),
    ("knee flexion", "left_knee_Z", "right_knee_Z"),
    ("ankle dorsiflexion", "left_ankle_Z", "right_ankle_Z"),
    ("shoulder flexion", "left_shoulder_Z", "right_shoulder_Z"),
    ("elbow flexion", "left_elbow_Z", "right_elbow_Z"),
)


@dataclass(frozen=True)
class Panel:
    """One plot of a figure: series over time sharing one vertical axis.

    Attributes:
        series: Legend label -> values, each of shape (F,), in the unit of ``ylabel``; NaN values
            leave gaps in the lines.
        ylabel: The vertical axis label, unit included (e.g. ``"residual [mm]"``).
        title: The title above the plot.
        ylim: The vertical axis range; None for matplotlib's, which starts at 0 when no value
            is negative (a residual or a fraction read from a zero baseline).
        highlight: The label of a series drawn thick and black (a mean over the others), or None.
    """

    series: dict[str, np.ndarray]
    ylabel: str
    title: str
    ylim: tuple[float, float] | None = None
    highlight: str | None = None


def joint_angle_panels(columns_deg: dict[str, np.ndarray]) -> list[Panel]:
    """The panels of angles.png from motion.mot's columns: one per row of `JOINT_ANGLES` whose
    columns are present, series labelled "left" and "right" (drawn solid and dashed).

    Args:
        columns_deg: column name -> values (F,) [deg], as motion.mot holds them.

    Returns:
        The panels, none for a motion without these columns (another model's).
    """
    return [Panel({"left": columns_deg[left], "right": columns_deg[right]}, f"{title} [deg]", title)
            for title, left, right in JOINT_ANGLES if left in columns_deg and right in columns_deg]


def _side_and_part(label: str) -> tuple[str | None, str]:
    """("left" | "right" | None, the label without its side): "LWrist", "left_knee_Z", "left"."""
    lowered = label.lower()
    for side in ("left", "right"):
        if lowered == side:
            return side, ""
        if lowered.startswith((side + "_", side + " ")):
            return side, label[len(side) + 1:]
    if len(label) > 1 and label[0] in "LR" and label[1].isupper():
        return ("left" if label[0] == "L" else "right"), label[1:]
    return None, label


def plot_series(
    path: str | os.PathLike[str],
    times: np.ndarray,
    series: dict[str, np.ndarray],
    ylabel: str,
    title: str,
    xlabel: str = "time [s]",
) -> None:
    """A PNG line plot of one or more series over time (:func:`plot_panels` with one panel)."""
    plot_panels(path, times, [Panel(series, ylabel, title)], xlabel)


def plot_panels(
    path: str | os.PathLike[str],
    times: np.ndarray,
    panels: list[Panel],
    xlabel: str = "time [s]",
) -> None:
    """A PNG of panels stacked over one time axis, each with legend, grid and axis labels.

    The figure is drawn with matplotlib's Agg canvas directly: no global backend is selected,
    so the caller's matplotlib state is left alone. 800 px wide, 450 px tall per panel up to two,
    then 300 px more per panel.

    Args:
        path: The .png file to write.
        times: Time of each sample, shape (F,) [s].
        panels: The plots, top first.
        xlabel: The horizontal axis label, unit included.

    Raises:
        InputError: No panel, a panel without series, a series whose shape is not (F,), or the
            file cannot be written.
    """
    times = np.asarray(times, dtype=float)
    if times.ndim != 1:
        raise InputError(f"times: expected shape (F,) [s], got {times.shape}")
    if not panels:
        raise InputError("panels: expected at least one panel, got none")
    checked = []
    for panel in panels:
        if not panel.series:
            raise InputError(f"panel {panel.title!r}: expected at least one series, got none")
        values_by_label = {}
        for label, values in panel.series.items():
            values = np.asarray(values, dtype=float)
            if values.shape != times.shape:
                raise InputError(f"series[{label!r}]: expected shape {times.shape} like times, got {values.shape}")
            values_by_label[label] = values
        checked.append((panel, values_by_label))

    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    height = 4.5 if len(panels) == 1 else 4.5 + 3.0 * (len(panels) - 1)
    figure = Figure(figsize=(8.0, height), dpi=100)
    FigureCanvasAgg(figure)
    for index, (panel, values_by_label) in enumerate(checked):
        axes = figure.add_subplot(len(panels), 1, index + 1)
        # Left and right of one part share its colour and differ in line style (solid, dashed), as
        # gait reports draw them; parts take tab10's colours, tab20's beyond ten.
        sides_and_parts = {label: _side_and_part(label) for label in values_by_label}
        parts = list(dict.fromkeys(part for _, part in sides_and_parts.values()))
        palette = colormaps["tab10" if len(parts) <= 10 else "tab20"]
        for label, values in values_by_label.items():
            side, part = sides_and_parts[label]
            if label == panel.highlight:
                axes.plot(times, values, label=label, linewidth=2.5, color="black", zorder=3)
            else:
                by_side = "tab:red" if side == "left" else "tab:blue"  # a series named by its side alone
                color = palette(parts.index(part) % palette.N) if part else by_side
                axes.plot(times, values, label=label, linewidth=1.4, color=color,
                          linestyle="--" if side == "right" else "-")
        if panel.ylim is not None:
            axes.set_ylim(*panel.ylim)
        elif all(np.nanmin(v, initial=0.0) >= 0.0 for v in values_by_label.values()):
            axes.set_ylim(bottom=0.0)
        axes.set_xlabel(xlabel)
        axes.set_ylabel(panel.ylabel)
        axes.set_title(panel.title)
        axes.grid(True, alpha=0.4)
        axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0)
    figure.tight_layout()
    write_atomically(path, lambda temporary: figure.savefig(temporary, format="png"))
