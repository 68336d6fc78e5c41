"""What a Dask worker runs: a participant's subject calibration, and one trial's `ibik track`.

Both catch every error of their own work and return it as data, so that one bad trial is one
failed row and never stops the batch; only a worker's death reaches the scheduler, which then
runs the task again on another worker.
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

from ibik_pin.app.batch.bookkeeping import missing_outputs
from ibik_pin.app.batch.summary import TrialOutcome, outcome_from_report
from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.exceptions import IbikError
from ibik_pin.human import load_human
from ibik_pin.subject.calibration import calibrate_static_trial
from ibik_pin.subject.calibration_result import write_calibration_figures
from ibik_pin.subject.urdf import write_subject_urdf

__all__ = ["OUTPUT_FILES", "SubjectOutcome", "calibrate_subject_once", "completed_outcome", "one_line", "run_trial",
           "worker_name"]

# What run_track writes into OUTDIR (app.outputs.write_outputs); with --overlay, also these
# and one overlay video per camera.
OUTPUT_FILES = ("joints.trc", "q.csv", "motion.mot", "motion.bvh", "model.osim", "report.json")
OVERLAY_FILES = ("residuals.png", "replay.html")


@dataclass(frozen=True)
class SubjectOutcome:
    """A participant's calibrated model: its URDF, or why it could not be made."""

    urdf: Path
    error: str = ""


def one_line(error: BaseException) -> str:
    """The error as one line; its type is named unless it is one of the package's own."""
    message = " ".join(str(error).split())
    return message if isinstance(error, IbikError) else f"{type(error).__name__}: {message}"


def worker_name() -> str:
    """The Dask worker running this task ("" outside one)."""
    try:
        from distributed import get_worker

        return str(get_worker().name)
    except (ImportError, ValueError):
        return ""


def calibrate_subject_once(static: Path, model: Path | None, urdf: Path) -> SubjectOutcome:
    """`ibik calibrate STATIC --out URDF [--model MODEL]` unless URDF is already there.

    The figures go to NAME.calibration.json beside it (as `ibik calibrate` writes them), before
    the URDF: the URDF's presence says the calibration is complete.
    """
    if urdf.is_file():
        return SubjectOutcome(urdf)
    try:
        body = load_human(model) if model is not None else load_human()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = calibrate_static_trial(static, body)
        staging = urdf.with_name(f".{urdf.name}.partial")
        notes = write_subject_urdf(result.body, staging)
        write_calibration_figures(urdf, static, body.urdf_path, result, notes)
        staging.replace(urdf)
    except Exception as error:  # any failure is this participant's, recorded for each of its trials
        return SubjectOutcome(urdf, f"subject calibration on {static} failed: {one_line(error)}")
    return SubjectOutcome(urdf)


def run_trial(name: str, job: TrackJob, subject: SubjectOutcome | None) -> TrialOutcome:
    """`ibik track` on one trial (its job built as the command builds it), tracked with the
    participant's calibrated model when there is one; returns its summary row."""
    subject_name = str(subject.urdf) if subject is not None else ""
    if subject is not None and subject.error:
        return TrialOutcome(name, "failed", subject=subject_name, worker=worker_name(), error=subject.error)
    if subject is not None:
        job = replace(job, model=subject.urdf, static=None)
    start = time.perf_counter()
    # A worker's warnings would be lost in its log: they go to the trial's row instead.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            report = run_track(job)
        except Exception as error:  # one trial's failure, whatever it is, must not stop the others
            return TrialOutcome(name, "failed", subject=subject_name, worker=worker_name(),
                                seconds=time.perf_counter() - start, warnings=_joined(caught),
                                error=one_line(error))
    return outcome_from_report(name, "ok", report.to_dict(), subject=subject_name, worker=worker_name(),
                               seconds=time.perf_counter() - start, warnings=_joined(caught))


def _joined(caught: list[warnings.WarningMessage]) -> str:
    """The distinct warning messages, each on one line, joined by " | "."""
    return " | ".join(dict.fromkeys(" ".join(str(warning.message).split()) for warning in caught))


def completed_outcome(name: str, out: Path, overlay: bool, subject: str) -> TrialOutcome | None:
    """The row of a trial whose outputs in `out` are complete (an earlier run), else None: every
    output the batch expects listed in OUTDIR's manifest, every listed file there with its size
    (batch.bookkeeping.missing_outputs), and report.json readable."""
    expected = OUTPUT_FILES + (OVERLAY_FILES if overlay else ())
    if missing_outputs(out, expected) is not None:
        return None
    try:
        report = json.loads((out / "report.json").read_text())
        return outcome_from_report(name, "skipped", report, subject=subject)
    except (OSError, ValueError, KeyError, TypeError):
        return None  # unreadable: tracked again
