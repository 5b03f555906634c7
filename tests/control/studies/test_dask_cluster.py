"""The documented Dask cluster: a real scheduler and a real worker started with scripts/dask_cluster.sh,
in processes of their own, run a study's trials (the scheduler must import the package to unpickle the
task graph: a scheduler from a plain shell fails every trial)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from quadruped_control.studies import run_trials
from quadruped_control.studies.trial import TrialSpec, run_batch, run_trial
from quadruped_control.studies.runner import run_trial_batches
from tests.repo import REPO_ROOT

pytest.importorskip("distributed", reason="the Dask cluster needs the 'distributed' package")

LAUNCHER = os.path.join(REPO_ROOT, "scripts", "dask_cluster.sh")
WS = os.environ.get("UQ_WS") or os.path.join(os.path.dirname(REPO_ROOT), os.path.basename(REPO_ROOT) + "_ws")


def _start(args, log):
    return subprocess.Popen(["bash", LAUNCHER] + args, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                            env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": os.environ.get("HOME", "/tmp"),
                                 "UQ_WS": WS})


def _stop(process):
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(10)


@pytest.fixture
def cluster(tmp_path):
    if not os.path.isfile(os.path.join(WS, "devel", "setup.bash")):
        pytest.skip("no catkin workspace at %s (scripts/setup.sh builds it)" % WS)
    if os.path.realpath(sys.prefix) != os.path.realpath(os.path.join(REPO_ROOT, ".venv")):
        # The launcher runs the project's venv; a client on another interpreter (CI's Python 3.8 job) would
        # talk to a cluster of other Python and Dask versions, which Dask refuses.
        pytest.skip("the client must run in the project's venv, as the cluster the launcher starts")
    scheduler_file = str(tmp_path / "scheduler.json")
    log = open(str(tmp_path / "cluster.log"), "w")
    processes = []
    try:
        # A plain environment: only what the launcher itself sets up lets the processes import the package.
        processes.append(_start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                 "--scheduler-file", scheduler_file], log))
        deadline = time.monotonic() + 60
        while not os.path.exists(scheduler_file):
            assert time.monotonic() < deadline and processes[0].poll() is None, open(str(tmp_path / "cluster.log")).read()
            time.sleep(0.2)
        time.sleep(0.2)
        with open(scheduler_file) as stream:
            address = json.load(stream)["address"]
        processes.append(_start(["worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"], log))
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(1, timeout=60)
        yield address
    finally:
        for process in reversed(processes):
            _stop(process)
        log.close()


def test_real_scheduler_and_worker_from_the_launcher_run_trials_and_batches(cluster, tmp_path):
    specs = [TrialSpec(label="a", setpoint_rpy_deg=(20.0, 0.0, 0.0), duration=2.0, quiet=True, keep_trace=False),
             TrialSpec(label="b", setpoint_rpy_deg=(0.0, 0.0, 20.0), duration=2.0, quiet=True, keep_trace=False)]
    on_cluster = run_trials(run_trial, specs, str(tmp_path / "trials"), dask_scheduler=cluster, progress=False)
    batched = run_trial_batches(run_batch, specs, str(tmp_path / "batched"), dask_scheduler=cluster, progress=False)
    local = [run_trial(spec) for spec in specs]
    for remote, batch, here in zip(on_cluster, batched, local):
        assert remote["metrics"]["geodesic"] == here["metrics"]["geodesic"]
        assert batch["engine"] == "batch"
        assert batch["metrics"]["geodesic"]["final_smoothed_deg"] == pytest.approx(
            here["metrics"]["geodesic"]["final_smoothed_deg"], abs=1e-9)


def test_launcher_refuses_an_unknown_role():
    result = subprocess.run(["bash", LAUNCHER, "client"], capture_output=True, text=True, timeout=60,
                            env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "UQ_WS": WS})
    assert result.returncode == 2 and "usage" in result.stderr
