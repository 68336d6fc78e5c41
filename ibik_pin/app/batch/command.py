"""`ibik batch ROOT --out OUTROOT`: the command's arguments and what it does with them.

The batch parser starts from `ibik track`'s own arguments, so every track option means the same
here and each trial's job is built by the very function that builds `ibik track`'s; the options
that name one trial's files are replaced: the batch finds them in each trial (batch.discovery).
This module imports nothing heavy: `ibik --help` loads it.
"""

from __future__ import annotations

import argparse
import os
import sys
import uuid
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ibik_pin.app.batch.summary import TrialOutcome
    from ibik_pin.app.job import TrackJob

__all__ = ["add_batch_arguments", "run_batch_command"]

PER_TRIAL_OPTIONS = ("--static", "--calibration", "--masks", "--videos", "--background")


class _FoundInEachTrial(argparse.Action):
    """A track option that names one trial's file: refused, the batch finds it in each trial."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: str | Sequence[Any] | None, option_string: str | None = None) -> None:
        parser.error(f"{option_string}: ibik batch finds it in each trial folder (see ibik batch --help)")


def add_batch_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the batch's arguments to a parser (conflict_handler="resolve") holding track's."""
    parser.add_argument("root", type=Path, help="the session folder: every trial under it is tracked")
    parser.add_argument("--out", type=Path, required=True,
                        help="OUTROOT: each trial's outputs go to OUTROOT/<its path under ROOT>, the "
                             "participants' calibrated models to OUTROOT/<participant>/subject.urdf, "
                             "the table of all trials to OUTROOT/summary.csv (and .parquet with pyarrow), every "
                             "run's rows appended to OUTROOT/runs.csv; a new or empty folder, or an "
                             "earlier batch's, outside ROOT")
    parser.add_argument("--targets", default="*.trc", metavar="PATTERN",
                        help="file name pattern of a trial's targets TRC, in the trial's folder or its "
                             "pose-3d/ (default: *.trc; files named *static* are static trials)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="address of a running Dask scheduler (tcp://host:port); its workers must "
                             "see ROOT and OUTROOT at the same paths (default: a cluster on this machine)")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="worker processes of the cluster started on this machine (default: one per core)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no closing summary")
    for option in PER_TRIAL_OPTIONS:
        parser.add_argument(option, action=_FoundInEachTrial, nargs="?", help=argparse.SUPPRESS)


def run_batch_command(arguments: argparse.Namespace, make_job: Callable[[argparse.Namespace], TrackJob]) -> int:
    """Track every trial under ROOT; returns the exit code: 0 if none failed, 1 if any did.

    Args:
        arguments: the parsed batch arguments.
        make_job: builds a TrackJob from `ibik track`'s arguments (the CLI's own function).

    Raises:
        IbikError: Dask missing, bad options, no trial found, an unreachable scheduler.
    """
    from ibik_pin.app.batch.runner import require_dask

    require_dask()
    from tqdm import tqdm

    from ibik_pin.app.batch.bookkeeping import check_outroot, claim_outroot, remove_leftovers
    from ibik_pin.app.batch.discovery import find_trials
    from ibik_pin.app.batch.runner import SubjectTask, TrialTask, dask_client, run_on_dask
    from ibik_pin.app.batch.summary import TrialOutcome, append_runs_log, earlier_records, write_summary
    from ibik_pin.app.batch.tasks import completed_outcome
    from ibik_pin.exceptions import InputError

    if arguments.workers is not None and (arguments.scheduler is not None or arguments.workers < 1):
        raise InputError(f"--workers: expected a positive number of workers and no --scheduler (the "
                         f"scheduler's cluster has its own workers), got {arguments.workers}")
    root, outroot = arguments.root.resolve(), arguments.out.resolve()
    make_job(arguments)  # the track options are checked once, before any trial (its paths are placeholders)
    if not root.is_dir():
        raise InputError(f"ROOT {arguments.root}: not a folder")
    check_outroot(root, outroot, str(arguments.out))
    trials = find_trials(root, arguments.targets, exclude=outroot)
    if not trials:
        raise InputError(f"ROOT {arguments.root}: no trial found (a folder holding a TRC matching "
                         f"{arguments.targets!r}, itself or in pose-3d/, or a videos/ folder of videos)")
    model = Path(arguments.model).resolve() if arguments.model is not None else None
    run = f"{datetime.now(timezone.utc):%Y-%m-%dT%H:%M:%SZ}-{uuid.uuid4().hex[:6]}"  # this run's id in runs.csv
    earlier = earlier_records(outroot)

    outcomes: list[TrialOutcome] = []
    tasks = []
    for trial in trials:
        name, out = trial.name.as_posix(), outroot / trial.name
        subject: SubjectTask | Path | None = None
        if trial.subject is not None and trial.subject.model is not None:
            subject = trial.subject.model
        elif trial.subject is not None and trial.subject.static is not None:
            subject = SubjectTask(trial.subject.static, model, outroot / trial.subject.folder / "subject.urdf")
        label = str(subject.urdf if isinstance(subject, SubjectTask) else subject or "")
        if trial.problem is not None:
            outcomes.append(TrialOutcome(name, "failed", subject=label, error=trial.problem))
            continue
        remove_leftovers(out)  # a killed worker's staging folder, a publish cut short
        done = completed_outcome(name, out, arguments.overlay, label)
        if done is not None:
            record = earlier.get(name, {})  # the run that tracked it: its worker, time and id
            done.worker, done.tracked_in = record.get("worker", ""), record.get("batch_run", "")
            done.seconds = float(record["seconds"]) if record.get("seconds") else None
            outcomes.append(done)
            continue
        job_arguments = argparse.Namespace(**{
            **vars(arguments), "targets": trial.targets, "static": None, "calibration": trial.calibration,
            "masks": trial.masks, "videos": trial.videos, "background": trial.background, "model": model,
            "out": out, "quiet": True, "read_ahead": "off"})  # a worker per core: one thread each
        tasks.append(TrialTask(name, make_job(job_arguments), subject))

    claim_outroot(outroot, root)
    with tqdm(total=len(trials), initial=len(outcomes), desc="trials", unit="trial",
              disable=True if arguments.quiet else None) as bar:
        failures = [sum(outcome.status == "failed" for outcome in outcomes)]

        def count(outcome: TrialOutcome) -> None:
            failures[0] += outcome.status == "failed"
            bar.set_postfix(failed=failures[0], refresh=False)
            bar.update()

        if tasks:
            workers = arguments.workers or os.cpu_count() or 1
            with dask_client(arguments.scheduler, workers) as client:
                outcomes += run_on_dask(client, tasks, outroot, count)
    for outcome in outcomes:
        if outcome.status != "skipped":
            outcome.tracked_in = run
    written = write_summary(outroot, outcomes) + [append_runs_log(outroot, run, outcomes)]
    failed = [outcome for outcome in outcomes if outcome.status == "failed"]
    for outcome in sorted(failed, key=lambda o: o.trial):
        print(f"ibik: trial {outcome.trial} failed: {outcome.error}", file=sys.stderr)
    if not arguments.quiet:
        tracked = sum(outcome.status == "ok" for outcome in outcomes)
        print(f"{len(outcomes)} trials: {tracked} tracked, {len(outcomes) - tracked - len(failed)} already done, "
              f"{len(failed)} failed; summary: {', '.join(str(path) for path in written)}")
    return 1 if failed else 0
