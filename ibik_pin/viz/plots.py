"""Plots of per-frame series (PNG); matplotlib is imported only when a plot is drawn.

matplotlib takes 0.5-0.7 s to import (measured on the development machine) and only the plots
need it: importing this module, as the tracking pipeline does, must not cost that when no plot is
asked for.
"""

from __future__ import annotations

import os

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.io.files import write_atomically

__all__ = ["plot_series"]


def plot_series(
    path: str | os.PathLike[str],
    times: np.ndarray,
    series: dict[str, np.ndarray],
    ylabel: str,
    title: str,
    xlabel: str = "time [s]",
) -> None:
    """A PNG line plot of one or more series over time, with legend, grid and axis labels.

    The figure is drawn with matplotlib's Agg canvas directly: no global backend is selected,
    so the caller's matplotlib state is left alone. NaN values leave gaps in the lines.

    Args:
        path: The .png file to write.
        times: Time of each sample, shape (F,) [s].
        series: Legend label -> values, each of shape (F,), in the unit of ``ylabel``.
        ylabel: The vertical axis label, unit included (e.g. ``"residual [mm]"``).
        title: The title above the plot.
        xlabel: The horizontal axis label, unit included.

    Raises:
        InputError: No series, or a series whose shape is not (F,), or the file cannot be
            written.
    """
    times = np.asarray(times, dtype=float)
    if times.ndim != 1:
        raise InputError(f"times: expected shape (F,) [s], got {times.shape}")
    if not series:
        raise InputError("series: expected at least one series, got none")
    checked = {}
    for label, values in series.items():
        values = np.asarray(values, dtype=float)
        if values.shape != times.shape:
            raise InputError(
                f"series[{label!r}]: expected shape {times.shape} like times, got {values.shape}"
            )
        checked[label] = values

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8.0, 4.5), dpi=100)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    for label, values in checked.items():
        axes.plot(times, values, label=label, linewidth=1.5)
    axes.set_xlabel(xlabel)
    axes.set_ylabel(ylabel)
    axes.set_title(title)
    axes.grid(True, alpha=0.4)
    axes.legend(loc="best")
    figure.tight_layout()
    write_atomically(path, lambda temporary: figure.savefig(temporary, format="png"))
