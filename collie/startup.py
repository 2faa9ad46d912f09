"""The stack's start, timed by part: each process of a `collie up` appends marks to one JSON-lines
file (OUT/logs/startup.jsonl, named by COLLIE_STARTUP_LOG) until the first segment is posted. A mark
names the work that just ended in that process, so the time (wall and CPU) since the process's
previous mark is that work's (benchmarks/bench_first_segment.py prints the split). Without the variable nothing is
written; the trainer stops marking once it has posted its first session (`done`)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from pydantic import BaseModel

LOG_ENV = "COLLIE_STARTUP_LOG"  # the file every part appends to
PART_ENV = "COLLIE_STARTUP_PART"  # which part this process is (service, trainer, labeling_ui)

_done = False


class StartupMark(BaseModel):
    """One line of startup.jsonl: `what` ended at wall time `t` (seconds since the epoch) in `part`,
    when the process had used `cpu` seconds of CPU (all its threads; on a busy machine the CPU
    split stays close to what a quiet one shows, while the wall split stretches)."""

    t: float
    cpu: float
    part: str
    pid: int
    what: str
    epoch: int | None = None


def mark(what: str, epoch: int | None = None) -> None:
    """Record that `what` just ended in this process (no-op outside a timed start)."""
    path = os.environ.get(LOG_ENV)
    if not path or _done:
        return
    line = StartupMark(
        t=time.time(),
        cpu=time.process_time(),
        part=os.environ.get(PART_ENV, "up"),
        pid=os.getpid(),
        what=what,
        epoch=epoch,
    )
    with open(path, "a") as f:  # one short write per line: the parts' lines never interleave
        f.write(line.model_dump_json(exclude_none=True) + "\n")


def done() -> None:
    """The first segment is out: this process marks nothing more."""
    global _done
    _done = True


def read_marks(path: Path) -> list[StartupMark]:
    """Every mark in the file, in time order (torn last lines of a process still writing skipped)."""
    marks = []
    for line in path.read_text().splitlines() if path.exists() else []:
        try:
            marks.append(StartupMark.model_validate(json.loads(line)))
        except (json.JSONDecodeError, ValueError):
            continue
    return sorted(marks, key=lambda m: m.t)
