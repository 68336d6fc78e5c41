"""`ibik batch --scheduler` on a real Dask cluster: `dask scheduler` and `dask worker` started as
separate processes on 127.0.0.1 (the `dask-scheduler` and `dask-worker` of older releases), and a
worker killed while it runs a trial: the trial must be run again elsewhere, none may go missing."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ibik_pin.cli import main
from ibik_pin.synthetic.trials import write_trial_tree

distributed = pytest.importorskip("distributed")  # the test extra installs it: these run in CI

CORRUPT = "P2/walk_2"
TRIALS = ["P1/walk_1", "P1/walk_2", "P1/walk_3", "P2/walk_1", CORRUPT, "P2/walk_3"]
START_TIMEOUT_S = 120.0
RUN_TIMEOUT_S = 600.0


def read_summary(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "summary.csv", newline="") as stream:
        return {row["trial"]: row for row in csv.DictReader(stream)}


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("cluster") / "root"
    write_trial_tree(root, trials_per_participant=(3, 3), frames=8)
    (root / CORRUPT / "targets.trc").write_text("not a TRC\n")
    return root


class Cluster:
    """A `dask scheduler` and named `dask worker` processes on 127.0.0.1, each its own process."""

    def __init__(self, folder: Path, allowed_failures: int = 3) -> None:
        self.folder = folder
        # How many workers may die running a task before the scheduler gives it up (Dask's default: 3).
        self.allowed_failures = allowed_failures
        self.environment = {**os.environ, "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": str(allowed_failures)}
        self.workers: dict[str, subprocess.Popen] = {}
        scheduler_file = folder / "scheduler.json"
        self.scheduler = self._start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                      "--scheduler-file", str(scheduler_file)], "scheduler")
        deadline = time.monotonic() + START_TIMEOUT_S
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            assert self.scheduler.poll() is None, (folder / "scheduler.log").read_text()
            assert time.monotonic() < deadline, "the scheduler did not start"
            time.sleep(0.1)
        self.address = json.loads(scheduler_file.read_text())["address"]

    def _start(self, arguments: list[str], log: str) -> subprocess.Popen:
        with open(self.folder / f"{log}.log", "w") as stream:
            return subprocess.Popen([sys.executable, "-m", "dask", *arguments], stdout=stream,
                                    stderr=subprocess.STDOUT, cwd=self.folder,
                                    env=self.environment)

    def add_worker(self, name: str) -> None:
        """A worker of one thread, without a nanny: killing its process removes it for good."""
        self.workers[name] = self._start([
            "worker", self.address, "--name", name, "--nthreads", "1", "--no-nanny", "--no-dashboard",
            "--host", "127.0.0.1"], name)

    def client(self):
        client = distributed.Client(self.address, timeout=START_TIMEOUT_S)
        client.wait_for_workers(len(self.workers), timeout=START_TIMEOUT_S)
        return client

    def stop(self) -> None:
        for process in [*self.workers.values(), self.scheduler]:
            if process.poll() is None:
                process.terminate()
        for process in [*self.workers.values(), self.scheduler]:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@pytest.fixture
def cluster(tmp_path, request):
    started = Cluster(tmp_path, getattr(request, "param", 3))
    yield started
    started.stop()


def test_a_batch_submitted_to_a_separate_scheduler_runs_on_its_worker(root, cluster, tmp_path):
    cluster.add_worker("w1")
    with cluster.client():
        pass  # the worker is up

    code = main(["batch", str(root), "--out", str(tmp_path / "out"), "--scheduler", cluster.address,
                 "--iterations", "3", "--quiet"])

    assert code == 1
    summary = read_summary(tmp_path / "out")
    assert sorted(summary) == TRIALS
    assert {name: row["status"] for name, row in summary.items() if row["status"] != "ok"} == {CORRUPT: "failed"}
    assert {row["worker"] for row in summary.values()} == {"w1"}  # run there, not in this process
    assert all((tmp_path / "out" / name / "report.json").is_file() for name in TRIALS if name != CORRUPT)


@pytest.mark.parametrize("cluster", [3, 0], indirect=True, ids=["retried", "given-up"])
def test_a_worker_killed_mid_trial_loses_no_trial(root, cluster, tmp_path):
    """Dask runs a task again on another worker when its worker dies, at most allowed-failures
    times; with 0 the killed trial must come back as a failed row, never go missing."""
    cluster.add_worker("doomed")
    cluster.add_worker("survivor")
    out = tmp_path / "out"
    with cluster.client() as client, open(tmp_path / "batch.log", "w") as log:
        batch = subprocess.Popen([sys.executable, "-m", "ibik_pin.cli", "batch", str(root), "--out", str(out),
                                  "--scheduler", cluster.address, "--iterations", "3", "--quiet"],
                                 stdout=log, stderr=subprocess.STDOUT)
        try:
            doomed = next(address for address, info in client.scheduler_info()["workers"].items()
                          if info["name"] == "doomed")
            deadline = time.monotonic() + RUN_TIMEOUT_S
            killed_key = None
            while killed_key is None:
                assert batch.poll() is None, "the batch ended before the worker could be killed"
                assert time.monotonic() < deadline, "the doomed worker never ran a trial"
                # the keys the doomed worker is running now (a lambda: pickled by value, since the
                # workers cannot import this test module)
                executing = client.run(lambda dask_worker: [str(key) for key, task in dask_worker.state.tasks.items()
                                                            if task.state == "executing"], workers=[doomed])
                # Not the corrupt trial: it fails in milliseconds wherever it runs, so killing its
                # worker tests nothing, and under load it was sometimes the one caught running.
                running = [key for key in executing.get(doomed, []) if key.startswith("ibik-track-")
                           and not key.startswith(f"ibik-track-{CORRUPT}-")]
                if running:
                    cluster.workers["doomed"].send_signal(signal.SIGKILL)
                    killed_key = running[0]
                time.sleep(0.01)
            code = batch.wait(timeout=RUN_TIMEOUT_S)
        finally:
            if batch.poll() is None:
                batch.kill()
        alive = [info["name"] for info in client.scheduler_info()["workers"].values()]

    assert alive == ["survivor"]
    assert code == 1, (tmp_path / "batch.log").read_text()
    summary = read_summary(out)
    assert sorted(summary) == TRIALS  # none missing
    killed_trial = next(name for name in TRIALS if killed_key.startswith(f"ibik-track-{name}-"))
    failed = {name: row["status"] for name, row in summary.items() if row["status"] != "ok"}
    if cluster.allowed_failures > 0:
        assert failed == {CORRUPT: "failed"}
        assert summary[killed_trial]["worker"] == "survivor"  # run again on the other worker
        assert (out / killed_trial / "report.json").is_file()
    else:  # the killed trial, and any other the doomed worker held, come back failed with the reason
        assert CORRUPT in failed and killed_trial in failed
        for name in set(failed) - {CORRUPT}:
            assert "not completed on the cluster" in summary[name]["error"], summary[name]
            assert "KilledWorker" in summary[name]["error"], summary[name]
