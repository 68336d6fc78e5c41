"""Running the trials on Dask distributed: a LocalCluster on this machine, or an existing scheduler.

Each participant's subject calibration is one task; each trial is one task that depends on its
participant's. Tasks return their outcome as data (batch.tasks), so a failed trial is a row. A
worker that dies takes its running tasks with it: the scheduler runs them again on another worker,
up to `distributed.scheduler.allowed-failures` times, and a task that still cannot finish comes
back as an error (KilledWorker) that is recorded as that trial's failure. Every trial therefore
ends as a row, none goes missing.
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from ibik_pin.app.batch.summary import TrialOutcome
from ibik_pin.app.batch.tasks import SubjectOutcome, calibrate_subject_once, one_line, run_trial
from ibik_pin.app.job import TrackJob
from ibik_pin.exceptions import IbikError

__all__ = ["INSTALL_HINT", "SubjectTask", "TrialTask", "dask_client", "require_dask", "run_on_dask"]

INSTALL_HINT = "ibik batch needs Dask distributed: pip install 'ibik_pin[batch]'"
CONNECT_TIMEOUT_S = 20


def require_dask() -> None:
    """Raise IbikError with the install command when Dask distributed is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError as error:
        raise IbikError(f"{INSTALL_HINT} ({error})") from error


@dataclass(frozen=True)
class SubjectTask:
    """A participant's calibration to run: static TRC, starting model, URDF to write."""

    static: Path
    model: Path | None
    urdf: Path


@dataclass(frozen=True)
class TrialTask:
    """A trial to track: its name, its job, and its participant's calibration (None if none)."""

    name: str
    job: TrackJob
    subject: SubjectTask | Path | None  # a calibration to run, a URDF to use as it is, or nothing


@contextmanager
def dask_client(scheduler: str | None, workers: int) -> Iterator:
    """A Dask Client: on `scheduler` when given, else on a LocalCluster of `workers` processes of
    one thread (the solver is single-threaded Python: threads would share one GIL)."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as error:
            raise IbikError(f"--scheduler {scheduler}: cannot connect: {one_line(error)}") from error
        with client:
            yield client
        return
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client


def run_on_dask(client, trials: list[TrialTask], outroot: Path,
                on_outcome: Callable[[TrialOutcome], None]) -> list[TrialOutcome]:
    """Submit every calibration and trial, collect one outcome per trial as they finish."""
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]  # two batches on one scheduler must not share task keys
    calibrations = {}
    for trial in trials:
        subject = trial.subject
        if isinstance(subject, SubjectTask) and subject.urdf not in calibrations:
            calibrations[subject.urdf] = client.submit(
                calibrate_subject_once, subject.static, subject.model, subject.urdf,
                key=f"ibik-calibrate-{subject.urdf.relative_to(outroot)}-{token}")
    futures = []
    for trial in trials:
        subject = trial.subject
        if isinstance(subject, SubjectTask):
            dependency = calibrations[subject.urdf]
        else:
            dependency = SubjectOutcome(subject) if subject is not None else None
        futures.append(client.submit(run_trial, trial.name, trial.job, dependency,
                                     key=f"ibik-track-{trial.name}-{token}"))
    names = {future.key: trial.name for future, trial in zip(futures, trials, strict=True)}
    outcomes = []
    for future in as_completed(futures):
        name = names[future.key]
        try:
            outcome = future.result()
        except Exception as error:  # the task never returned: its workers died (KilledWorker) or it was lost
            outcome = TrialOutcome(name, "failed", error=f"not completed on the cluster: {one_line(error)}")
        outcomes.append(outcome)
        on_outcome(outcome)
        future.release()
    return outcomes
