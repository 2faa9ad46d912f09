"""Reading a run folder's files (summary.json, config.json, task.json, eval_latest.npz, …) so that a
missing or damaged one is an error naming the file, for every command that reads run folders; and
writing its JSON files whole (a kill mid-write leaves the old file, never half of a new one), or a
whole new run folder at once (`folder_written_whole`)."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import stat
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from collie.whole_files import write_whole


class RunFolderError(ValueError):
    """A run folder's file cannot be read as what it should hold; the message names the file."""


class ResumeError(ValueError):
    """A run folder that `--resume` cannot continue: a file missing or damaged, named in the message.
    Here, not beside the checkpoint code, so that `collie train` loads torch only after it has set
    OpenMP's variables (trainer/threads.py)."""


def read_json_object(path: Path) -> dict[str, Any]:
    """`path`'s JSON object; RunFolderError naming the file and why if it is missing, not JSON or
    not an object (a file cut short by a full disk, or written by hand)."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise RunFolderError(f"{path}: missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RunFolderError(f"{path}: not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise RunFolderError(f"{path}: not a JSON object")
    return data


def write_json(path: Path, data: Any) -> None:
    """`data` as indented JSON at `path`, renamed into place whole."""
    text = json.dumps(data, indent=2).encode()
    write_whole(path, lambda f: f.write(text))


def copy_whole(source: Path, target: Path) -> None:
    """`source` copied to `target`, renamed into place whole."""
    with open(source, "rb") as f:
        write_whole(target, lambda out: shutil.copyfileobj(f, out))


def read_arrays(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The arrays `keys` of the .npz file at `path`; RunFolderError naming the file and why if it is
    missing, damaged (cut short, not an npz) or lacks one of them."""
    try:
        loaded = np.load(path)
        if not isinstance(loaded, np.lib.npyio.NpzFile):  # a bare .npy under the name: one array
            raise ValueError("a single array, not an archive of named arrays")
        with loaded as f:
            found = {k: f[k] for k in keys if k in f.files}
    except FileNotFoundError:
        raise RunFolderError(f"{path}: missing") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise RunFolderError(f"{path}: not a readable .npz ({exc})") from None
    missing = [k for k in keys if k not in found]
    if missing:
        raise RunFolderError(f"{path}: no {', '.join(missing)} in it")
    return found


@contextlib.contextmanager
def writing_into(folder: Path) -> Iterator[None]:
    """A full disk's (or quota's) refusal of a write names no file: raised again naming `folder`, so
    that `collie` says which path could not be written (collie/cli.py's line)."""
    try:
        yield
    except OSError as exc:
        if exc.filename is None and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise OSError(exc.errno, exc.strerror, str(folder)) from None
        raise


@contextlib.contextmanager
def folder_written_whole(out: Path) -> Iterator[Path]:
    """A new folder beside `out` to write a run folder into, renamed to `out` when the block ends;
    if it fails (a full disk, Ctrl-C) removed with what it holds, and `out` too where this made it,
    so that no half-written run is left. `out` must be absent or empty (the rename replaces an empty
    folder). An error naming a file in the new folder names its place in `out`."""
    made = not out.exists()
    out.mkdir(parents=True, exist_ok=True)  # a read-only disk, a path through a file: named as `out`
    building = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        os.chmod(building, stat.S_IMODE(out.stat().st_mode))  # mkdtemp's is 0700
        try:
            yield building
        except OSError as exc:
            raise _naming_out(exc, building, out) from None
        building.replace(out)
    except BaseException:
        shutil.rmtree(building, ignore_errors=True)
        if made:
            with contextlib.suppress(OSError):
                out.rmdir()
        raise


def _naming_out(exc: OSError, building: Path, out: Path) -> OSError:
    """`exc` with each path inside `building` replaced by the same path inside `out`."""

    def moved(name: str | bytes | None) -> str | None:
        if name is None:
            return None
        path = Path(os.fsdecode(name))
        return str(out / path.relative_to(building)) if path.is_relative_to(building) else str(path)

    return OSError(exc.errno, exc.strerror, moved(exc.filename), None, moved(exc.filename2))
