"""The stack's start, timed by part: each process of a `collie up` appends marks to one JSON-lines
file (OUT/logs/startup.jsonl, named by COLLIE_STARTUP_LOG) until the first segment is posted. A mark
names the work that just ended in that process, so the time (wall and CPU) since the process's
previous mark is that work's (benchmarks/bench_first_segment.py prints the split). Without the
variable nothing is written; the trainer stops marking once it has posted its first session (`done`).

Lines are `collie.schemas.StartupMark`s, written here with json alone: every process marks its
start before it imports anything heavy (pydantic included), so the marks cost the start nothing."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collie.schemas import StartupMark

LOG_ENV = "COLLIE_STARTUP_LOG"  # the file every part appends to
PART_ENV = "COLLIE_STARTUP_PART"  # which part this process is (service, trainer, labeling_ui)

_done = False


def mark(what: str, epoch: int | None = None) -> None:
    """Record that `what` just ended in this process (no-op outside a timed start)."""
    path = os.environ.get(LOG_ENV)
    if not path or _done:
        return
    line = {"t": time.time(), "cpu": time.process_time(), "part": os.environ.get(PART_ENV, "up"), "pid": os.getpid()}
    line |= {"what": what, **({"epoch": epoch} if epoch is not None else {})}
    text = json.dumps(line) + "\n"
    for _ in range(2):  # a FIFO's reader (the tests' paced marks) may close just as this opened it: once more
        try:
            with open(path, "a") as f:  # one short write per line: the parts' lines never interleave
                f.write(text)
            return
        except BrokenPipeError:
            continue
        except OSError:  # a full or read-only disk: the timeline is a measurement, never a reason to stop
            return


def done() -> None:
    """The first segment is out: this process marks nothing more."""
    global _done
    _done = True


def read_marks(path: Path) -> list[StartupMark]:
    """Every mark in the file, in time order (a torn last line of a killed process skipped)."""
    from pydantic import ValidationError

    from collie.schemas import StartupMark

    marks = []
    for line in path.read_text().splitlines() if path.exists() else []:
        try:
            marks.append(StartupMark.model_validate_json(line))
        except ValidationError:
            continue
    return sorted(marks, key=lambda m: m.t)
