"""Process plumbing for the commands that start or guard other processes (`collie up`, `collie
sweep`, `collie train`, the service's parsing worker): children that end with their parent, and a
lock file that one process, and the children it hands the descriptor to, holds."""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import os
import signal
import sys
from pathlib import Path

PR_SET_PDEATHSIG = 1  # linux/prctl.h
_LIBC = ctypes.CDLL(None, use_errno=True) if sys.platform == "linux" else None  # loaded once, not in each child


def end_with_parent(parent: int | None = None) -> None:
    """In a child (a `preexec_fn`, a worker's initializer): SIGTERM from the kernel when the thread
    that started it ends, even by SIGKILL (Linux's PR_SET_PDEATHSIG; elsewhere nothing), instead of
    running on unsupervised. `parent`: its pid, for a parent that died before this call."""
    if _LIBC is None:
        return
    with contextlib.suppress(OSError, AttributeError):
        _LIBC.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if parent is not None and os.getppid() != parent:
        os.kill(os.getpid(), signal.SIGTERM)


def running(pid: object) -> bool:
    """A live process has this pid (another user's too; a zombie, which has ended, has not)."""
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's: it exists
        pass
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1][:1]
    except (OSError, IndexError):  # no /proc here, or it ended just now: existence is what is known
        return True
    return state != "Z"


class LockHeld(Exception):
    """Another process holds the lock; `holder` is the pid it wrote ("" if none)."""

    def __init__(self, holder: str) -> None:
        super().__init__(holder)
        self.holder = holder


def lock_holder(path: Path) -> str | None:
    """The pid ("" if unknown) of the process holding the lock at `path` now, else None (no lock
    file, or none holds it); nothing is taken or written."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:  # shared: it conflicts with the holder's exclusive lock, and needs no write access (NFS)
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return os.read(fd, 32).decode(errors="replace").strip()
    except OSError:  # a file system without locks: nobody known to hold it
        return None
    finally:
        os.close(fd)  # and with it a lock it took
    return None


def hold_lock(path: Path) -> int:
    """An exclusive lock on `path` (made if missing, readable by its owner only) for as long as the
    returned descriptor is open here or in a child it was passed to; the file names our pid.
    LockHeld if another process holds it."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 32).decode(errors="replace").strip()
        os.close(fd)
        raise LockHeld(holder) from None
    try:
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
    except OSError:  # a full disk: the lock is ours, and so is its file's removal (no pid in it)
        with contextlib.suppress(OSError):
            os.unlink(path)
        os.close(fd)
        raise
    return fd
