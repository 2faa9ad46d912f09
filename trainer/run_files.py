"""Reading a run folder's files (summary.json, config.json, task.json, eval_latest.npz, …) so that a
missing or damaged one is an error naming the file, for every command that reads run folders; and
writing its JSON files whole (a kill mid-write leaves the old file, never half of a new one), or a
whole new run folder at once (`folder_written_whole`)."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import secrets
import shutil
import stat
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from collie.whole_files import make_folder, write_whole


class RunFolderError(ValueError):
    """A run folder's file cannot be read as what it should hold; the message names the file."""


class ResumeError(ValueError):
    """A run folder that `--resume` cannot continue: a file missing or damaged, named in the message.
    Here, not beside the checkpoint code, so that `collie train` loads torch only after it has set
    OpenMP's variables (trainer/threads.py)."""


def has_checkpoint(folder: str | Path) -> bool:
    """Whether `folder` holds a run's checkpoint.pt (what `--resume` continues from)."""
    return (Path(folder) / "checkpoint.pt").is_file()


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


# The hidden folders `folder_written_whole` leaves beside OUT while it works, `.OUT.<8 hex>.KIND`:
# the dot keeps every run-folder search (`run_folders`) from reading them.
BEING_WRITTEN = ".partial"  # never a whole copy: the new one being built, or the old one being removed
MOVED_ASIDE = ".old"  # the whole older copy, between the two renames that swap in a new one


def run_folders(root: Path) -> list[Path]:
    """The run folders (those with summary.json) at or below `root`, in a stable order; none in a
    hidden folder below it (`.NAME.*.partial`, `.NAME.*.old` beside a run being written: not a run)."""
    found = (summary.parent for summary in root.rglob("summary.json"))
    return sorted(f for f in found if not any(part.startswith(".") for part in f.relative_to(root).parts))


def unsummarised_run_folders(root: Path) -> list[Path]:
    """The folders at or below `root` where a run began (config.json naming its env and method) but
    wrote no summary.json yet: one still training, or one killed before its first summary; none
    in a hidden folder, as run_folders."""
    found = []
    for config in root.rglob("config.json"):
        folder = config.parent
        if (folder / "summary.json").exists() or any(p.startswith(".") for p in folder.relative_to(root).parts):
            continue
        try:
            held = read_json_object(config)
        except RunFolderError:
            held = {}
        if isinstance(held.get("env"), str) and isinstance(held.get("method"), str):
            found.append(folder)
    return sorted(found)


@contextlib.contextmanager
def folder_written_whole(out: Path, replace: bool = False) -> Iterator[Path]:
    """A new folder beside `out` to write a run folder into, renamed to `out` when the block ends;
    if it fails (a full disk, Ctrl-C) removed with what it holds, and `out` and its parents too
    where this made them, so that no half-written run is left. `out` must be absent or empty (the
    rename replaces an empty folder), unless `replace`: then the folder there is swapped for the
    new one (`_swap_in`), and left as it was if the block fails. What a killed one left beside
    `out` is recovered first (`recover_beside`). An error naming a file in the new folder names its
    place in `out`."""
    recover_beside(out)
    made = [folder for folder in (out, *out.parents) if not folder.exists()]  # `out` first, then up
    building: Path | None = None
    try:
        make_folder(out)  # a read-only disk, a path through a file: named as `out`
        building = _hidden_beside(out, BEING_WRITTEN)
        os.chmod(building, stat.S_IMODE(out.stat().st_mode))  # the mode `out` has, or the umask gave it
        try:
            yield building
        except OSError as exc:
            raise _naming_out(exc, building, out) from None
        if replace and any(out.iterdir()):
            _swap_in(building, out)
        else:
            building.replace(out)
    except BaseException:
        if building is not None:
            shutil.rmtree(building, ignore_errors=True)
        with contextlib.suppress(OSError):  # stops at the first one not empty
            for folder in made:
                folder.rmdir()
        raise


def _hidden_beside(out: Path, kind: str) -> Path:
    """A new empty hidden folder beside `out`, `.OUT.<8 hex>KIND`."""
    folder = out.with_name(f".{out.name}.{secrets.token_hex(4)}{kind}")
    folder.mkdir()
    return folder


def _left_beside(out: Path, kind: str) -> list[Path]:
    """The hidden `kind` folders `_hidden_beside` made for `out` (not for another name that starts
    with it: `.run.x.<hex>.partial` is run.x's)."""
    if not out.parent.is_dir():
        return []
    pattern = re.compile(rf"\.{re.escape(out.name)}\.[0-9a-f]{{8}}{re.escape(kind)}")
    return sorted(p for p in out.parent.iterdir() if pattern.fullmatch(p.name) and p.is_dir())


def _swap_in(building: Path, out: Path) -> None:
    """`building` put in place of the whole folder `out`: that one moved aside (`.OUT.*.old`), the
    new one renamed in, then the old one removed under `building`'s `.partial` name (a half-removed
    copy is never taken for a whole one). A failed rename puts the old one back; a kill between the
    two renames leaves no `out` but both whole copies beside it, and `recover_beside` puts the old
    one back. Neither copy is ever lost."""
    aside = _hidden_beside(out, MOVED_ASIDE)
    out.replace(aside)  # over the empty folder just made: a name no other writer uses
    try:
        building.replace(out)
    except BaseException:
        aside.replace(out)
        raise
    with contextlib.suppress(OSError):  # the new one is in: its old copy left is recovered next time
        aside.replace(building)
        shutil.rmtree(building, ignore_errors=True)


def recover_beside(out: Path) -> None:
    """Undo what a `folder_written_whole` killed (kill -9, a power cut) left beside `out`: its
    `.partial` folders removed; a moved-aside whole copy (`.old`) put back if `out` is missing (killed
    between `_swap_in`'s two renames: the last complete copy is the one the run was refreshing from),
    else removed (killed after them). Assumes one writer of `out` at a time."""
    for partial in _left_beside(out, BEING_WRITTEN):
        shutil.rmtree(partial, ignore_errors=True)
    for old in _left_beside(out, MOVED_ASIDE):
        if not out.exists():
            old.replace(out)
        else:
            shutil.rmtree(old, ignore_errors=True)


def _naming_out(exc: OSError, building: Path, out: Path) -> OSError:
    """`exc` with each path inside `building` replaced by the same path inside `out`."""

    def moved(name: str | bytes | None) -> str | None:
        if name is None:
            return None
        path = Path(os.fsdecode(name))
        return str(out / path.relative_to(building)) if path.is_relative_to(building) else str(path)

    return OSError(exc.errno, exc.strerror, moved(exc.filename), None, moved(exc.filename2))
