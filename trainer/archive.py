"""`collie archive RUN|ROOT… --out DIR`: keep finished runs' results, small enough to commit.

A robot run folder holds ≈ 90 MB (replay, checkpoint) and is gone when its machine is; its results
are a few files of kilobytes. This copies those — summary.json, config.json, task.json,
sweep_run.json, downstream.json, metrics.jsonl and the final evaluation (eval_latest.npz) — into
DIR/<the run folder's name> (a `collie up` stack's, OUT/trainer: its stack's), a folder `collie
report` reads like the run itself (tables, skill figures, diagnostics). A ROOT (a folder holding run
folders, as `collie sweep --out` writes) has each finished run below it archived at the same
relative path under DIR; the unfinished ones, and those `collie report` would leave out (a file it
cannot read: summary.json not JSON or with a figure that is no number, eval_latest.npz cut short…;
trainer.report.checked_run), are named with why and left out; such a run folder given itself is
refused in one line (exit 2). A run whose name the archive already holds for another configuration
is refused naming what differs (where and how each ran aside: trainer.same_run.NOT_THE_RUN); the
others are archived, and the exit code is 2. No checkpoint or replay is copied, so an archived run
cannot be resumed or given a downstream task; run those before archiving. Each copy is written
whole (trainer.run_files.folder_written_whole): one that fails midway (a full disk) leaves no run
folder, or when refreshing an archived run its older copy as it was; the hidden folders it works in
are no runs to `collie report` or here, and what a kill -9 left of them the next archive recovers.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from collie.stack_folder import STACK_LOCK, STACK_RUN
from trainer.methods import METHODS, matters
from trainer.report import checked_run
from trainer.run_files import (
    RunFolderError,
    copy_whole,
    folder_written_whole,
    read_json_object,
    recover_beside,
    run_folders,
    writing_into,
)
from trainer.same_run import comparable, differing_keys, only_more_epochs, run_config
from trainer.sweep import is_finished
from trainer.task_choice import TASK_JSON

REQUIRED = ("summary.json", "eval_latest.npz")
OPTIONAL = ("config.json", TASK_JSON, "sweep_run.json", "downstream.json", "metrics.jsonl")


SHOWN_KEYS = 4  # a refusal names at most this many differing keys with their values


class ArchiveError(ValueError):
    """The folder is not a finished run (or `collie report` would leave it out: a file it cannot
    read), or the archive already holds another run of its name."""


def another_run(held: Path, source: Path) -> str | None:
    """How the run archived at `held` differs from `source`'s ("seed 0 archived, 7 here"), None if
    it is the same run (where and how each ran aside: trainer.same_run.NOT_THE_RUN; and keys its
    method does not read, trainer.methods.matters: `--diayn` to COLLIE), or that run extended
    since to more epochs."""
    old, new = run_config(held), run_config(source)
    method = new.get("method")
    keys = [k for k in differing_keys(old, new) if method not in METHODS or matters(k, str(method))]
    a, b = comparable(old), comparable(new)
    if not keys or only_more_epochs(keys, a, b):  # the run extended since
        return None
    shown = [f"{k} {a.get(k)!r} archived, {b.get(k)!r} here" for k in keys[:SHOWN_KEYS]]
    more = f" and {len(keys) - SHOWN_KEYS} more" if len(keys) > SHOWN_KEYS else ""
    return "; ".join(shown) + more


def archive(source: Path, out_root: Path, relative: Path | None = None) -> Path:
    """Copy `source`'s results into `out_root`/<relative, default source's name>; returns that
    folder. Archiving the same run again refreshes it (a downstream task run since, say, or the same
    run from another folder), swapping the new copy in only once it is whole; another run of the same
    name (a different configuration) is refused, naming what differs."""
    for name in REQUIRED:
        if not (source / name).exists():
            raise ArchiveError(f"{source} has no {name}: not a run folder, or its final skills were not saved")
    try:
        summary = read_json_object(source / "summary.json")
        if not is_finished(source):
            raise ArchiveError(f"{source} is not finished (status {summary.get('status')!r})")
        checked_run(source)  # an archive holds only what the report counts
        out = out_root / (relative or archive_name(source))
        if out.resolve() == source.resolve():
            raise ArchiveError(f"{source} is already in {out_root}")
        recover_beside(out)  # an archive killed mid-refresh: its older copy back in place, to compare with
        differs = another_run(out, source) if (out / "summary.json").exists() else None
        if differs:
            raise ArchiveError(f"{out} holds another run of that name ({differs}); remove it first")
    except RunFolderError as exc:  # the message names the file
        raise ArchiveError(str(exc)) from None
    with folder_written_whole(out, replace=True) as new:  # a failure midway leaves the older copy, or none
        for name in REQUIRED + OPTIONAL:
            if (source / name).exists():
                copy_whole(source / name, new / name)
    return out


def runs_below(root: Path) -> tuple[list[Path], list[Path], list[str]]:
    """The finished run folders below `root`, the unfinished ones, each in a stable order, and why
    each folder whose summary.json cannot be read, or finished run the report would leave out, was
    left out (naming the file)."""
    finished: list[Path] = []
    unfinished: list[Path] = []
    unreadable: list[str] = []
    for folder in run_folders(root):  # none in a hidden folder: an archive being written
        try:
            read_json_object(folder / "summary.json")
            if is_finished(folder):
                checked_run(folder)
        except RunFolderError as exc:
            unreadable.append(str(exc))
            continue
        (finished if is_finished(folder) else unfinished).append(folder)
    return finished, unfinished, unreadable


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("runs", nargs="+", help="finished run folders, or folders holding them (searched recursively)")
    p.add_argument(
        "--out", default="results", help="the archive: a run goes into OUT/<its folder's name> (default: ./results)"
    )


def archive_name(source: Path) -> str:
    """A run's name in the archive: its folder's, but a `collie up` stack's run (OUT/trainer, the
    same name in every stack) goes by its stack's folder."""
    folder = source.resolve()
    if folder.name == STACK_RUN and (folder.parent / STACK_LOCK).exists():
        return folder.parent.name
    return folder.name


def jobs_in(given: Path, out_root: Path) -> list[tuple[Path, Path | None]]:
    """(run folder, its path under the archive or None for its name) for `given`: a run folder, a
    `collie up` stack's folder (its run), or a root holding run folders (its unfinished and
    unreadable ones named on stdout); ArchiveError if it is none of them."""
    if not given.is_dir():
        raise ArchiveError(f"{given} is not a folder")
    if (given / STACK_LOCK).exists() and (given / STACK_RUN).is_dir():
        given = given / STACK_RUN
    if (given / "summary.json").exists():
        return [(given, None)]
    finished, unfinished, unreadable = runs_below(given)
    if not finished and not unfinished and not unreadable:
        raise ArchiveError(f"{given} holds no run folder (none has summary.json)")
    target = out_root.resolve()
    holder = next((f for f in (*finished, *unfinished) if f.resolve() in (target, *target.parents)), None)
    if holder is not None:  # as into_itself refuses it for a run folder given
        raise ArchiveError(f"--out {out_root} is inside the run folder {holder}; give a folder outside it")
    for left in unfinished:
        print(f"left out (not finished): {left}")
    for why in unreadable:
        print(f"left out (unreadable): {why}")
    return [(f, f.relative_to(given)) for f in finished if out_root.resolve() not in f.resolve().parents]


def into_itself(given: Path, out_root: Path) -> str | None:
    """Why archiving `given` into `out_root` would copy nothing or copy a run into itself: --out is
    the folder given (every run below it would be left out as already archived), or lies inside a
    run folder (one given, or any other). None otherwise (an archive inside a root given is left
    out of it)."""
    if out_root.resolve() == given.resolve():
        return f"--out {out_root} is the folder given to archive; give another folder"
    target = out_root.resolve()
    holder = next((f for f in (target, *target.parents) if (f / "summary.json").is_file()), None)
    if holder is not None:  # any run's, not only one given: its archive would read as part of that run
        return f"--out {out_root} is inside the run folder {holder}; give a folder outside it"
    return None


def run(args: argparse.Namespace) -> int:
    out_root = Path(args.out)
    if out_root.exists() and not out_root.is_dir():
        print(f"collie archive: error: --out {out_root} is a file, not a folder", file=sys.stderr)
        return 2
    jobs: list[tuple[Path, Path | None]] = []
    try:  # every folder given is checked before anything is copied
        for given in map(Path, args.runs):
            why = into_itself(given, out_root)
            if why is not None:
                raise ArchiveError(why)
            jobs += jobs_in(given, out_root)
    except ArchiveError as exc:
        print(f"collie archive: error: {exc}", file=sys.stderr)
        return 2
    refused: list[Path] = []
    for source, relative in jobs:  # one refused run does not keep the others out of the archive
        try:
            with writing_into(out_root):
                out = archive(source, out_root, relative)
        except ArchiveError as exc:
            print(f"collie archive: error: {exc}", file=sys.stderr)
            refused.append(source)
            continue
        size = sum(f.stat().st_size for f in out.iterdir())
        print(f"{source} → {out} ({size / 1e3:.0f} kB)")
    if refused and len(jobs) > 1:
        names = ", ".join(map(str, refused))
        print(f"collie archive: {len(refused)} of {len(jobs)} runs not archived: {names}", file=sys.stderr)
    return 2 if refused else 0
