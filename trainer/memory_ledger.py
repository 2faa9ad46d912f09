"""Memory promised to runs on this machine that they have not touched yet, so that runs started side
by side (a sweep's `--jobs`, two terminals) do not each count the same free memory.

The memory plan (trainer/memory_plan.py) compares a run's floor with what the machine has free. But
Linux lends lazily: a run that passed a minute ago has taken little of its replay yet, and the next
run would find that memory still free; both would pass, and the kernel would kill one of them hours
later. So each run that passes writes LEDGER/<pid>.json: its floor and its resident set then. The next
run's check takes off, for each entry whose process lives, floor − (resident now − resident then),
the part of its floor the kernel has not lent it yet. An entry whose process is gone (or whose pid
another process took) is dropped. One lock orders runs that check at the same instant.

The ledger is per user: LEDGER is $COLLIE_MEMORY_LEDGER, or collie-memory-<uid> in the temporary
folder. Where it cannot be used (a read-only /tmp), a run is checked as before, alone.
"""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import json
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from collie.whole_files import write_whole
from trainer.memory_plan import NotEnoughMemory, available_bytes

LEDGER_ENV = "COLLIE_MEMORY_LEDGER"
PROC = Path("/proc")


@dataclass(frozen=True)
class Promise:
    """A run's floor, granted when its process (pid, started at `started` clock ticks after boot)
    had `resident` bytes resident."""

    pid: int
    started: int
    floor: int
    resident: int


def ledger_folder() -> Path:
    given = os.environ.get(LEDGER_ENV)
    return Path(given) if given else Path(tempfile.gettempdir()) / f"collie-memory-{os.getuid()}"


def process_start(pid: int) -> int | None:
    """When `pid` started (clock ticks after boot; field 22 of /proc/PID/stat), None if no such
    process: with the pid, it names one process, which a reused pid does not match."""
    try:
        after_name = (PROC / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()
        return int(after_name[19])  # fields from the 3rd on, after the command's name in parentheses
    except (OSError, IndexError, ValueError):
        return None


def resident(pid: int) -> int | None:
    try:
        return int((PROC / str(pid) / "statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, IndexError, ValueError):
        return None


def untouched(promise: Promise) -> int | None:
    """The part of `promise`'s floor its process has not taken yet; None if the process is gone."""
    now = resident(promise.pid)
    if now is None or process_start(promise.pid) != promise.started:
        return None
    return max(0, promise.floor - max(0, now - promise.resident))


def promises(folder: Path) -> Iterator[tuple[Path, Promise]]:
    for path in sorted(folder.glob("*.json")):
        try:
            yield path, Promise(**json.loads(path.read_text()))
        except (OSError, ValueError, TypeError):  # half a file from a full disk, or not ours: not a promise
            with contextlib.suppress(OSError):
                path.unlink()


def promised_elsewhere(folder: Path) -> tuple[int, list[int]]:
    """Bytes promised to other live runs and not yet touched, and their pids; a dead run's entry
    is removed."""
    held, pids = 0, list[int]()
    for path, promise in promises(folder):
        if promise.pid == os.getpid():
            continue
        left = untouched(promise)
        if left is None:
            with contextlib.suppress(OSError):
                path.unlink()
        elif left > 0:
            held += left
            pids.append(promise.pid)
    return held, pids


def check_beside_others(what: str, needed: int, available: int | None = None) -> None:
    """NotEnoughMemory if `needed` bytes exceed what is free (`available`, read now if None) less
    what other runs here were promised and have not taken yet."""
    free = available_bytes() if available is None else available
    if free is None:
        return
    held, pids = 0, list[int]()
    with contextlib.suppress(OSError):
        held, pids = promised_elsewhere(ledger_folder())
    if needed > free - held:
        raise NotEnoughMemory(what, needed, free, held=held, holders=tuple(pids))


def reserve(what: str, needed: int, available: int | None = None) -> None:
    """`check_beside_others`, then `needed` written down as this process's promise (until it ends),
    both under the ledger's lock: of two runs that check at once, the second counts the first."""
    folder = ledger_folder()
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        lock = open(folder / ".lock", "a")  # noqa: SIM115  # held while the promise is checked and written
    except OSError:
        check_beside_others(what, needed, available)  # no ledger here: checked alone, as before
        return
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        check_beside_others(what, needed, available)
        pid, started, now = os.getpid(), process_start(os.getpid()), resident(os.getpid())
        if started is None or now is None:  # no /proc: nothing to compare a promise with later
            return
        entry = folder / f"{pid}.json"
        promise = Promise(pid=pid, started=started, floor=needed, resident=now)
        with contextlib.suppress(OSError):  # a full disk: this run passed; the next counts it as free
            write_whole(entry, lambda f: f.write(json.dumps(promise.__dict__).encode()))
            atexit.register(entry.unlink, missing_ok=True)
