"""One row per trial: what `ibik batch` did with it, and the table of all of them (CSV, Parquet).

A row is filled from the trial's report.json (the one just written, or the one found when the
trial was already done), so a re-run's summary is as complete as the first run's. summary.csv is
the table of the latest run; every run's rows are also appended to OUTROOT/runs.csv (with the run's
id first), which no run rewrites but to append: the history of the batch. A trial done by an
earlier run keeps, in the latest summary, the worker, seconds and run id of the run that tracked it.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from ibik_pin.io.files import write_atomically, write_text_atomically

__all__ = ["RUNS_LOG", "STATUSES", "TrialOutcome", "append_runs_log", "earlier_records", "outcome_from_report",
           "write_summary"]

RUNS_LOG = "runs.csv"

STATUSES = ("ok", "skipped", "failed")  # tracked now, done by an earlier run, failed


@dataclass
class TrialOutcome:
    """One row of the summary.

    Attributes:
        trial: the trial's folder relative to ROOT (its outputs: OUTROOT/trial).
        status: "ok" (tracked by this run), "skipped" (complete outputs found) or "failed".
        frames: frames tracked.
        frame_rate_hz: the targets' frame rate [Hz].
        solve_fps: frames solved per second of solver time, on the worker that ran it [Hz].
        mean_residual_mm: end-effector residual, mean over the frames [mm].
        max_residual_mm: its largest value [mm].
        mean_overlap: the image criterion at the solutions, mean over frames and views.
        limit_hit_frames: frames where a joint was at a limit.
        dropped_target_frames: frames where a target was absent.
        subject: the model the trial was tracked with: a calibrated URDF, or "" (scaled from its
            own targets, or --model).
        worker: the Dask worker that ran it ("" when skipped or never run).
        seconds: wall time of the trial on its worker [s] (None when not run now).
        warnings: what `ibik track` warned about while tracking it, " | " between messages.
        error: why it failed, one line ("" when it did not).
        tracked_in: the id of the batch run that tracked it or failed it (for a skipped trial, an
            earlier run's; "" when unknown).
    """

    trial: str
    status: str
    frames: int | None = None
    frame_rate_hz: float | None = None
    solve_fps: float | None = None
    mean_residual_mm: float | None = None
    max_residual_mm: float | None = None
    mean_overlap: float | None = None
    limit_hit_frames: int | None = None
    dropped_target_frames: int | None = None
    subject: str = ""
    worker: str = ""
    seconds: float | None = None
    warnings: str = ""
    error: str = ""
    tracked_in: str = ""


def _millimetres(value: float | None) -> float | None:
    return None if value is None else 1000.0 * value


def outcome_from_report(trial: str, status: str, report: dict[str, Any], **extra: Any) -> TrialOutcome:
    """A row from report.json's content (TrackingReport.to_dict() or the file read back)."""
    overlaps = [value for values in report["overlap_per_view"].values() for value in values if value is not None]
    residual = report["end_effector_residual_m"]
    return TrialOutcome(
        trial=trial, status=status, frames=report["frames"], frame_rate_hz=report["frame_rate_hz"],
        solve_fps=report["solve_frames_per_second"], mean_residual_mm=_millimetres(residual["mean"]),
        max_residual_mm=_millimetres(residual["max"]),
        mean_overlap=math.fsum(overlaps) / len(overlaps) if overlaps else None,
        limit_hit_frames=len(report["joint_limit_hits"]),
        dropped_target_frames=len(report["frames_with_dropped_targets"]), **extra,
    )


def write_summary(out: Path, outcomes: list[TrialOutcome]) -> list[Path]:
    """OUTROOT/summary.csv, and summary.parquet when pyarrow is installed; returns the files written."""
    names = [field.name for field in fields(TrialOutcome)]
    rows = [asdict(outcome) for outcome in sorted(outcomes, key=lambda outcome: outcome.trial)]
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=names, lineterminator="\n")
    writer.writeheader()
    writer.writerows({name: "" if row[name] is None else row[name] for name in names} for row in rows)
    written = [out / "summary.csv"]
    write_text_atomically(written[0], text.getvalue())
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    types = {"trial": pa.string(), "status": pa.string(), "subject": pa.string(), "worker": pa.string(),
             "warnings": pa.string(), "error": pa.string(), "tracked_in": pa.string(),
             "frames": pa.int64(), "limit_hit_frames": pa.int64(),
             "dropped_target_frames": pa.int64()}
    schema = pa.schema([(name, types.get(name, pa.float64())) for name in names])
    table = pa.Table.from_pylist(rows, schema=schema)
    written.append(out / "summary.parquet")
    write_atomically(written[1], lambda temporary: pq.write_table(table, str(temporary)))
    return written


def _csv_text(names: list[str], rows: list[dict[str, Any]], header: bool) -> str:
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=names, lineterminator="\n")
    if header:
        writer.writeheader()
    writer.writerows({name: "" if row.get(name) is None else row.get(name) for name in names} for row in rows)
    return text.getvalue()


def earlier_records(out: Path) -> dict[str, dict[str, str]]:
    """Each trial's last record in OUTROOT/runs.csv with status "ok" (empty without a log)."""
    records: dict[str, dict[str, str]] = {}
    try:
        with open(out / RUNS_LOG, newline="", encoding="utf-8") as stream:
            for row in csv.DictReader(stream):
                if row.get("status") == "ok" and row.get("trial"):
                    records[row["trial"]] = row
    except (OSError, UnicodeDecodeError, csv.Error):
        return {}
    return records


def append_runs_log(out: Path, run: str, outcomes: list[TrialOutcome]) -> Path:
    """Append this run's rows to OUTROOT/runs.csv (made with its header when absent), the run's
    id in the first column. The file is rewritten whole through a temporary file, so that a
    killed run leaves the earlier history as it was; a log with other columns (another version's)
    keeps every row and column, the new ones added."""
    names = ["batch_run"] + [field.name for field in fields(TrialOutcome)]
    rows = [{"batch_run": run, **asdict(outcome)} for outcome in sorted(outcomes, key=lambda o: o.trial)]
    path = out / RUNS_LOG
    try:
        earlier = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        earlier = ""
    header = ",".join(names) + "\n"
    if not earlier or earlier.startswith(header):
        text = (earlier or header) + _csv_text(names, rows, header=False)
    else:
        reader = csv.DictReader(io.StringIO(earlier))
        old_rows = list(reader)
        every = names + [name for name in (reader.fieldnames or []) if name not in names]
        text = _csv_text(every, [*old_rows, *rows], header=True)
    write_text_atomically(path, text)
    return path
