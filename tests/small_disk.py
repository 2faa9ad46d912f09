"""A small file system of a test's own (a tmpfs) to fill or mount read-only: full and read-only
disks as the kernel makes them. Skipped where this process may not mount one (not root, or a
container without CAP_SYS_ADMIN)."""

from __future__ import annotations

import contextlib
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


@contextlib.contextmanager
def small_disk(where: Path, size: str = "1m", read_only: bool = False) -> Iterator[Path]:
    """`where` (made here) as a tmpfs of `size`, unmounted at the end (lazily if still busy)."""
    where.mkdir()
    options = f"size={size}" + (",ro" if read_only else "")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {mounted.stderr.decode().strip()}")
    try:
        yield where
    finally:
        if subprocess.run(["umount", str(where)]).returncode != 0:  # busy: detach it, never leave it behind
            subprocess.run(["umount", "-l", str(where)], check=True)


def fill(disk: Path) -> None:
    """Every byte of `disk` taken by a file named filler, until a write fails."""
    with open(disk / "filler", "wb") as f, contextlib.suppress(OSError):
        while True:
            f.write(b"\0" * 65536)
            f.flush()
