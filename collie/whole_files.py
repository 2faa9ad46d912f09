"""Files written whole: into NAME.partial beside the file, then renamed over it in one step, so a
reader (or a process killed mid-write) never finds half of one. Shared by the trainer's run
folders and checkpoints, `collie up`'s children.json and the labeling UI's --info-json."""

from __future__ import annotations

import errno
import os
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

# What a file system answers a write when the machine, not the program, is at fault: read-only,
# full, over quota. Commands say it in a line (collie/cli.py, collie train); any other OSError is a bug.
UNWRITABLE = (errno.EROFS, errno.ENOSPC, errno.EDQUOT)


def write_whole(path: Path, write: Callable[[BinaryIO], object], sync: bool = False) -> None:
    """What `write` writes to a file, at `path`, renamed into place whole; a failed write (a full
    disk) leaves the old file as it was and no .partial behind. PATH.partial, not PATH with its
    suffix swapped: `/tmp` would have become `/tmp.tmp`. `sync`: on disk before the rename (a
    checkpoint must survive a power cut, not only a killed process). A path that is no regular
    file, such as /dev/null or a FIFO, or anything in /dev, is written in place: renamed over,
    /dev/null would become a plain file for every program on the machine (as root)."""
    if not_replaceable(path):
        with open(path, "wb") as f:
            write(f)
        return
    partial = path.with_name(path.name + ".partial")
    try:
        with open(partial, "wb") as f:
            write(f)
            if sync:
                f.flush()
                os.fsync(f.fileno())
        partial.replace(path)
    finally:
        partial.unlink(missing_ok=True)


def not_replaceable(path: Path) -> bool:
    """A path whose file a rename must not replace: a device, FIFO or socket, or anything in /dev
    (/dev/stdout is a link). A link elsewhere is replaced, not followed: one planted in /tmp must
    not turn a write into a write of whatever it points at."""
    in_dev = path.absolute().parts[:2] == ("/", "dev")
    return in_dev or (path.exists() and not path.is_file() and not path.is_dir())


NEARLY_FULL = 1 << 20  # bytes free under which a disk is called full (a log line, a small file fail there)


def nearly_full(folder: Path) -> int | None:
    """The bytes free on `folder`'s disk where they are under NEARLY_FULL, else None (also where
    the disk cannot be asked)."""
    try:
        room = os.statvfs(folder)
    except OSError:
        return None
    free = room.f_bavail * room.f_frsize
    return free if free < NEARLY_FULL else None


def read_only_disk(folder: Path) -> bool:
    """Whether `folder` is on a file system mounted read-only (which root cannot write either)."""
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


class FolderRefused(FileNotFoundError):
    """mkdir's "No such file or directory" for a folder whose parents are there: a file system
    that makes no folders (/proc, /sys). Any other FileNotFoundError is a bug to show whole."""


def make_folder(path: Path) -> None:
    """`path` and its parents made where absent (FolderRefused where the file system makes none)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileNotFoundError as exc:
        raise FolderRefused(exc.errno, exc.strerror, exc.filename) from None


def broken_link(exc: OSError) -> str | None:
    """ "PATH: a link to TARGET, which does not exist" when `exc` is mkdir's refusal of a dangling
    link on the way (a folder linked to an unmounted disk, say): it says only "File exists"."""
    name = exc.filename
    if exc.errno != errno.EEXIST or name is None or not os.path.islink(name) or os.path.exists(name):
        return None
    return f"{name}: a link to {os.readlink(name)}, which does not exist"
