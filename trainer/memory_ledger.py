"""Memory promised to runs on this machine that they have not touched yet, so that runs started side
by side (a sweep's `--jobs`, two terminals) do not each count the same free memory.

The memory plan (trainer/memory_plan.py) compares a run's floor with what the machine has free. But
Linux lends lazily: a run that passed a minute ago has taken little of its replay yet, and the next
run would find that memory still free; both would pass, and the kernel would kill one of them hours
later. So each run that passes writes LEDGER/<pid>.json: its floor and its anonymous memory then
(RssAnon + VmSwap: a replay's pages, resident or swapped out, which neither swapping nor reclaim of
the libraries' file pages takes back from the count). The next run's check takes off, for each
entry whose process lives, floor − (anonymous now − anonymous then), the part of its floor the
kernel has not lent it yet. An entry whose process is gone (or whose pid another process took) is
dropped. One lock orders runs that check at the same instant.

The ledger is per user: LEDGER is $COLLIE_MEMORY_LEDGER, or collie-memory-<uid> in the temporary
folder, used only if it is this user's folder and nobody else may write in it (a folder another
user made at that name could hold a FIFO or links). Where it cannot be used (a read-only /tmp,
someone else's folder), a run is checked alone, as before the ledger. A process promises one floor:
a second Trainer built in the same process replaces the first's promise.
"""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import json
import os
import re
import stat
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from collie.whole_files import write_whole
from trainer.memory_plan import NotEnoughMemory, available_bytes

LEDGER_ENV = "COLLIE_MEMORY_LEDGER"
PROC = Path("/proc")
PROMISE_KEYS = ("pid", "started", "floor", "anonymous")
ENTRY = re.compile(r"^[0-9]+\.json$")  # <pid>.json: no other file in the folder is read or removed
FORGET_AT_EXIT: list[Path] = []  # this process's entry, removed at its exit (once, however many promises)


@dataclass(frozen=True)
class Promise:
    """A run's floor, granted when its process (pid, started at `started` clock ticks after boot)
    had `anonymous` bytes of anonymous memory."""

    pid: int
    started: int
    floor: int
    anonymous: int


def ledger_folder() -> Path:
    """The ledger's folder, made if absent; OSError if it cannot be made or is not this user's
    alone."""
    given = os.environ.get(LEDGER_ENV)
    folder = Path(given) if given else Path(tempfile.gettempdir()) / f"collie-memory-{os.getuid()}"
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    st = folder.lstat()
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid() or st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        raise PermissionError(f"{folder} is not a folder of this user's that only it may write in")
    return folder


def process_start(pid: int) -> int | None:
    """When `pid` started (clock ticks after boot; field 22 of /proc/PID/stat), None if no such
    process: with the pid, it names one process, which a reused pid does not match."""
    try:
        after_name = (PROC / str(pid) / "stat").read_bytes().rsplit(b")", 1)[1].split()
        return int(after_name[19])  # fields from the 3rd on, after the command's name in parentheses
    except (OSError, IndexError, ValueError):
        return None


def anonymous_memory(pid: int) -> int | None:
    """`pid`'s anonymous memory, resident or swapped out (RssAnon + VmSwap of /proc/PID/status)."""
    try:
        fields = dict(line.split(b":", 1) for line in (PROC / str(pid) / "status").read_bytes().splitlines())
        return sum(int(fields[key].split()[0]) * 1024 for key in (b"RssAnon", b"VmSwap"))
    except (OSError, KeyError, IndexError, ValueError):
        return None


def untouched(promise: Promise) -> int | None:
    """The part of `promise`'s floor its process has not taken yet; None if the process is gone."""
    now = anonymous_memory(promise.pid)
    if now is None or process_start(promise.pid) != promise.started:
        return None
    return max(0, promise.floor - max(0, now - promise.anonymous))


def promises(folder: Path) -> Iterator[tuple[Path, Promise]]:
    """The folder's promises; a file that holds none (not four whole numbers) is passed over."""
    for path in sorted(folder.iterdir()):
        if not ENTRY.match(path.name):
            continue
        try:
            fields = json.loads(path.read_text())
            if isinstance(fields, dict) and all(type(fields.get(key)) is int for key in PROMISE_KEYS):
                yield path, Promise(**{key: fields[key] for key in PROMISE_KEYS})
        except (OSError, ValueError):
            continue


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
    with contextlib.suppress(OSError):  # no usable ledger: checked alone
        held, pids = promised_elsewhere(ledger_folder())
    if needed > free - held:
        raise NotEnoughMemory(what, needed, free, held=held, holders=tuple(pids))


def reserve(what: str, needed: int, available: int | None = None) -> None:
    """`check_beside_others`, then `needed` written down as this process's promise (until it ends),
    both under the ledger's lock: of two runs that check at once, the second counts the first."""
    try:
        folder = ledger_folder()
        lock = open(folder / ".lock", "a")  # noqa: SIM115  # held while the promise is checked and written
    except OSError:
        check_beside_others(what, needed, available)
        return
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        check_beside_others(what, needed, available)
        pid = os.getpid()
        started, anonymous = process_start(pid), anonymous_memory(pid)
        if started is None or anonymous is None:  # no /proc: nothing to compare a promise with later
            return
        entry = folder / f"{pid}.json"
        promise = Promise(pid=pid, started=started, floor=needed, anonymous=anonymous)
        with contextlib.suppress(OSError):  # a full disk: this run passed; the next counts it as free
            write_whole(entry, lambda f: f.write(json.dumps(promise.__dict__).encode()))
            if not FORGET_AT_EXIT:
                atexit.register(entry.unlink, missing_ok=True)
                FORGET_AT_EXIT.append(entry)
