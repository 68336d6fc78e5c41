"""`ibik calibrate`: the subject's model fitted on a static trial, written as a URDF with its figures."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

from ibik_pin.exceptions import IbikError, IbikWarning, InputError
from ibik_pin.human import load_human
from ibik_pin.subject.calibration import calibrate_static_trial
from ibik_pin.subject.calibration_result import CalibrationResult, write_calibration_figures
from ibik_pin.subject.urdf import write_subject_urdf

__all__ = ["CalibrationRun", "parse_frame_range", "run_calibrate"]


@dataclass(frozen=True)
class CalibrationRun:
    """What `ibik calibrate` did: the fit, and the figures file written beside the subject's URDF."""

    result: CalibrationResult
    figures: Path


def run_calibrate(static: Path, out: Path, model: Path | None = None, frames: str | None = None) -> CalibrationRun:
    """Fit the human (or `model`) on the static trial's frames FIRST:LAST (`frames`; None: all, at
    most 10 spread over them), write the subject's URDF to `out` and its figures beside it; each
    note of the URDF's writing is an IbikWarning."""
    frame_range = parse_frame_range(frames) if frames else (None, None)
    if out.suffix.lower() != ".urdf":
        raise IbikError(f"--out: expected a file name ending in .urdf, got {str(out)!r}")
    for option, given in (("the static trial", static), ("--model", model)):
        if given is not None and out.resolve() == Path(given).resolve():
            raise IbikError(f"--out {out}: it is {option}, which writing the subject would replace; "
                            "choose another file name")
    body = load_human(model) if model is not None else load_human()
    result = calibrate_static_trial(static, body, frame_range)
    notes = write_subject_urdf(result.body, out)
    figures = write_calibration_figures(out, static, body.urdf_path, result, notes)
    for note in notes:
        warnings.warn(note, IbikWarning, stacklevel=1)
    return CalibrationRun(result, figures)


def parse_frame_range(text: str) -> tuple[int | None, int | None]:
    """``FIRST:LAST`` (TRC frame numbers, both included; either may be left out) as a pair.

    Raises:
        InputError: not of that form, or FIRST after LAST.
    """
    first, colon, last = text.partition(":")
    try:
        bounds = (int(first) if first.strip() else None, int(last) if last.strip() else None)
    except ValueError:
        bounds = None
    if not colon or bounds is None:
        raise InputError(f"--frames: expected FIRST:LAST (TRC frame numbers, e.g. 1:30), got {text!r}")
    if bounds[0] is not None and bounds[1] is not None and bounds[0] > bounds[1]:
        raise InputError(f"--frames: FIRST must not be after LAST, got {text!r}")
    return bounds
