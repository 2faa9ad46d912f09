"""What a child process of `collie up` said went wrong: the last telling line of its log."""

from __future__ import annotations

import re
from pathlib import Path

from collie.whole_files import nearly_full

EXCEPTION_LINE = re.compile(r"[A-Za-z_][\w.]*(Error|Exception): ")


def last_error(log: Path, since: int = 0) -> str:
    """The last line a child wrote to its log (from byte `since`: its latest start's) that says what
    went wrong (empty if none): one of our commands' "collie …: error:" lines, else an exception's
    line, else any line naming an error."""
    try:
        with open(log, "rb") as f:
            f.seek(since)
            lines = f.read().decode(errors="replace").splitlines()
    except OSError:
        return ""
    said = [line.strip() for line in lines if line.strip()]
    ours = [line for line in said if line.startswith("collie ") and ": error:" in line]  # our CLIs' own words
    raised = [line for line in said if EXCEPTION_LINE.match(line)]  # a traceback's last line
    other = [line for line in said if "error" in line.lower() and not line.startswith("(Background on this error")]
    if not said:  # nothing: on a full disk the child's own words about it could not be written either
        return full_disk(log)
    return (ours or raised or other or said)[-1][:300]


def full_disk(log: Path) -> str:
    """ "nothing in its log: the disk under FOLDER is full (N KB free)", or "" where it is not."""
    free = nearly_full(log.parent)
    return "" if free is None else f"nothing in its log: the disk under {log.parent} is full ({free // 1024} KB free)"
