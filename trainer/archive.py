"""`collie archive RUN… --out DIR`: keep a finished run's results, small enough to commit.

A robot run folder holds ≈ 90 MB (replay, checkpoint) and is gone when its machine is; its results
are a few files of kilobytes. This copies those — summary.json, config.json, task.json,
sweep_run.json, downstream.json, metrics.jsonl and the final evaluation (eval_latest.npz) — into
DIR/<the run folder's name>, a folder `collie report` reads like the run itself (tables, skill
figures, diagnostics). No checkpoint or replay is copied, so an archived run cannot be resumed or
given a downstream task; run those before archiving.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from trainer.task_choice import TASK_JSON

REQUIRED = ("summary.json", "eval_latest.npz")
OPTIONAL = ("config.json", TASK_JSON, "sweep_run.json", "downstream.json", "metrics.jsonl")


class ArchiveError(ValueError):
    """The folder is not a finished run, or the archive already holds another run of its name."""


def archive(source: Path, out_root: Path) -> Path:
    """Copy `source`'s results into `out_root`/<source's name>; returns that folder. Archiving the
    same run again refreshes it (a downstream task run since, say); another run of the same name
    (a different configuration) is refused."""
    for name in REQUIRED:
        if not (source / name).exists():
            raise ArchiveError(f"{source} has no {name}: not a run folder, or its final skills were not saved")
    summary = json.loads((source / "summary.json").read_text())
    if summary.get("status") != "finished":
        raise ArchiveError(f"{source} is not finished (status {summary.get('status')!r})")
    out = out_root / source.resolve().name
    if out.resolve() == source.resolve():
        raise ArchiveError(f"{source} is already in {out_root}")
    held = out / "summary.json"
    if held.exists() and json.loads(held.read_text()).get("config") != summary.get("config"):
        raise ArchiveError(f"{out} holds another run of that name (its configuration differs); remove it first")
    out.mkdir(parents=True, exist_ok=True)
    for name in REQUIRED + OPTIONAL:
        if (source / name).exists():
            shutil.copyfile(source / name, out / name)
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("runs", nargs="+", help="finished run folders")
    p.add_argument("--out", default="results", help="the archive: each run goes into OUT/<its folder's name>")


def run(args: argparse.Namespace) -> int:
    for source in args.runs:
        try:
            out = archive(Path(source), Path(args.out))
        except ArchiveError as exc:
            print(f"collie archive: error: {exc}", file=sys.stderr)
            return 2
        size = sum(f.stat().st_size for f in out.iterdir())
        print(f"{source} → {out} ({size / 1e3:.0f} kB)")
    return 0
