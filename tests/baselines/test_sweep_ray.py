"""`collie sweep --ray ADDRESS` on a real Ray cluster: a head node started here (2 CPUs, its own temp
dir), two smoke runs, then a rerun that skips both."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import ray  # noqa: F401 - the `sweep` extra: a missing Ray is an error, not a skip

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def ray_head() -> Iterator[str]:
    temp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # short: Ray's unix socket paths must fit
    log = Path(temp) / "head.log"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_USAGE_STATS_ENABLED": "0"}  # workers import this tree
    cmd = [sys.executable, "-m", "ray.scripts.scripts", "start", "--head", "--port", "0", "--num-cpus", "2"]
    cmd += ["--node-ip-address", "127.0.0.1", "--include-dashboard=false", "--disable-usage-stats"]
    cmd += ["--temp-dir", temp, "--object-store-memory", str(100 * 2**20), "--block"]
    with log.open("wb") as out:
        head = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (found := re.search(r"ray start --address='([^']+)'", log.read_text())):
            assert head.poll() is None and time.monotonic() < deadline, log.read_text()[-3000:]
            time.sleep(0.5)
        yield found.group(1)
    finally:
        head.send_signal(signal.SIGTERM)  # it drains, then stops every process it started
        try:
            head.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait()
        shutil.rmtree(temp, ignore_errors=True)


def sweep(address: str, out: Path) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "collie.cli", "sweep", "--ray", address, "--env", "point", "--tasks", "north"]
    cmd += ["--methods", "metra", "--seeds", "2", "--preset", "smoke", "--out", str(out), "--no-report"]
    cmd += ["--", "--epochs", "3"]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)})


def test_sweep_on_a_ray_cluster_runs_every_run_and_a_rerun_skips_them(ray_head: str, tmp_path: Path) -> None:
    first = sweep(ray_head, tmp_path)
    assert first.returncode == 0, first.stdout[-2000:] + first.stderr[-2000:]
    runs = [tmp_path / f"point-north-metra-s{seed}" for seed in (0, 1)]
    for run in runs:
        summary = json.loads((run / "summary.json").read_text())
        assert summary["status"] == "finished" and summary["epochs_done"] == 3
    logs = {run: run.with_suffix(".log").stat().st_size for run in runs}
    again = sweep(ray_head, tmp_path)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "2 runs, 2 already finished" in again.stdout
    assert {run: run.with_suffix(".log").stat().st_size for run in runs} == logs  # nothing trained again
