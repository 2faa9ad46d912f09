"""make bench-first-segment: how long a new user waits, in `make demo`'s stack (point, north, cpu:
service, trainer and labeling UI, as `collie up` starts them), for the first segment to label,
with one CPU-bound process beside it (as a browser rendering WebGL in software is) and alone.

Target (issue 11): `first_segment_s` ≤ 45 s with the busy process (it was 886 s with torch's default
threads; 33 s on a quiet machine). JSON (runs/bench/first_segment.json): first_segment_s (busy),
first_segment_quiet_s.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from record import record

from collie.client import CollieClient

TIMEOUT_S = 600.0


def busy() -> None:
    while True:
        pass


def first_segment(tmp: Path) -> float:
    """Seconds from `collie up` to a pending query on the service."""
    info = tmp / "info.json"
    cmd = [sys.executable, "-m", "collie.cli", "up", "--env", "point", "--task", "north", "--preset", "cpu"]
    cmd += ["--port", "0", "--ui-port", "0", "--out", str(tmp / "stack"), "--info-json", str(info)]
    start = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        while not info.exists():
            if proc.poll() is not None or time.monotonic() - start > TIMEOUT_S:
                raise RuntimeError("collie up did not come up")
            time.sleep(0.2)
        meta = json.loads(info.read_text())
        with CollieClient(meta["api"], meta["tokens"]["operator"]) as client:
            while (queue := client.run(meta["run_id"]).queue).pending + queue.leased == 0:
                if proc.poll() is not None or time.monotonic() - start > TIMEOUT_S:
                    raise RuntimeError("no segment to label in time")
                time.sleep(0.2)
        return time.monotonic() - start
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        quiet = first_segment(Path(tmp) / "quiet")
        print(f"first segment to label, quiet machine: {quiet:.1f} s")
        loop = mp.Process(target=busy, daemon=True)
        loop.start()
        try:
            shared = first_segment(Path(tmp) / "busy")
        finally:
            loop.terminate()
        print(f"first segment to label, one busy process beside it: {shared:.1f} s (target ≤ 45 s)")
    record("first_segment", {"first_segment_s": shared, "first_segment_quiet_s": quiet})


if __name__ == "__main__":
    main()
