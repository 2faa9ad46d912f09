"""`collie sweep --ray ADDRESS` on a real Ray cluster: a head node started here (2 CPUs, its own temp
dir), two smoke runs, then a rerun that skips both."""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
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


def epochs_logged(run: Path) -> list[int]:
    """The epochs in `run`'s metrics.jsonl (a last line still being written is left out)."""
    metrics = run / "metrics.jsonl"
    lines = metrics.read_text().splitlines() if metrics.exists() else []
    epochs = []
    for line in lines:
        with contextlib.suppress(json.JSONDecodeError, KeyError):
            epochs.append(json.loads(line)["epoch"])
    return epochs


def interrupt_when(address: str, out: Path, ready: Callable[[], bool]) -> tuple[int, str]:
    """Start a Ray sweep of three endless point runs (two at a time on the head's 2 CPUs), Ctrl-C
    it twice once `ready()`, and return its exit code and stderr."""
    cmd = [sys.executable, "-m", "collie.cli", "sweep", "--ray", address, "--env", "point", "--tasks", "north"]
    cmd += ["--methods", "metra", "--seeds", "3", "--preset", "smoke", "--out", str(out), "--no-report", "--"]
    cmd += ["--epochs", "100000", "--eval-every", "1", "--checkpoint-every", "100000"]  # no checkpoint but the last
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 240
        while not ready():
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail(proc.communicate()[1][-3000:])
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        proc.send_signal(signal.SIGINT)  # twice: each training still gets one SIGTERM, and checkpoints
        _, err = proc.communicate(timeout=240)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, err


def test_an_interrupted_ray_sweep_stops_its_runs_with_a_checkpoint_and_a_rerun_resumes_them(
    ray_head: str, tmp_path: Path
) -> None:
    runs = [tmp_path / f"point-north-metra-s{seed}" for seed in range(3)]  # Ray picks which two run first

    def logged(minimum: dict[Path, int]) -> list[Path]:
        return [r for r in runs if len(epochs_logged(r)) and max(epochs_logged(r)) >= minimum.get(r, 1)]

    code, err = interrupt_when(ray_head, tmp_path, lambda: sum(len(epochs_logged(r)) >= 2 for r in runs) >= 2)
    assert code == 130, err[-3000:]
    assert "collie sweep: interrupted; 2 run(s) stopped, 1 not started; rerun the same command to resume" in err
    first = {}
    for run in [
        r for r in runs if r.exists()
    ]:  # each training got its SIGTERM: a final checkpoint, not a killed process
        summary = json.loads((run / "summary.json").read_text())
        assert summary["status"] == "interrupted" and (run / "checkpoint.pt").exists(), summary
        first[run] = summary["epochs_done"]
    assert len(first) == 2
    [queued] = [r for r in runs if r not in first]
    assert not queued.exists()  # queued, cancelled, never started

    beyond = {r: e + 1 for r, e in first.items()}
    code, err = interrupt_when(
        ray_head, tmp_path, lambda: len([r for r in logged(beyond) if r in first]) >= 1 and len(logged(beyond)) >= 2
    )
    assert code == 130, err[-3000:]
    resumed = [r for r in logged(beyond) if r in first]
    for run in resumed:  # resumed from the checkpoint: its epochs go on from where it stopped
        assert json.loads((run / "summary.json").read_text())["epochs_done"] > first[run]
        assert epochs_logged(run) == sorted(set(epochs_logged(run))), epochs_logged(run)
