"""Permission refusals, checked as root too: root may go anywhere (CI runs as root), so the code
under test runs in a forked child that drops to nobody first; it answers by exit code and stderr."""

from __future__ import annotations

import importlib
import os
import shutil
import sys
import tempfile
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

NOBODY = 65534


@contextmanager
def closed_folder(mode: int) -> Iterator[Path]:
    """A folder with `mode` inside one anybody may enter (pytest's tmp_path is root's alone)."""
    shared = Path(tempfile.mkdtemp(dir="/tmp"))
    folder = shared / "closed"
    try:
        shared.chmod(0o755)
        folder.mkdir(mode=mode)
        yield folder
    finally:
        folder.chmod(0o700)
        shutil.rmtree(shared)


def as_nobody(fn: Callable[[], int], preload: tuple[str, ...] = ()) -> tuple[int, str]:
    """fn's return code and what it wrote to stderr, run as nobody where we are root; 99 if it raised.
    `preload` names the modules fn imports: nobody may not read root's Python (here under /root)."""
    for name in preload:
        importlib.import_module(name)
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        code = 99
        try:
            sys.stderr = os.fdopen(write, "w")
            if os.geteuid() == 0:
                os.setgroups([])  # root's supplementary groups (often root's own) go too
                os.setgid(NOBODY)
                os.setuid(NOBODY)
            code = fn()
        except BaseException as exc:
            print(f"raised {exc!r}\n{traceback.format_exc()}", file=sys.stderr)
        finally:
            sys.stderr.flush()
            os._exit(code)
    os.close(write)
    with os.fdopen(read) as f:
        err = f.read()
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), err
