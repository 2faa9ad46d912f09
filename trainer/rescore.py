"""`collie rescore RUN --task TASK`: judge a finished run of a task-free method (METRA, LSD, DIAYN:
no labels, w ≡ 1) by another task's rule, without training it again.

Such a method never reads its task while it trains: the task enters only the evaluation. So its run
on Ant North and its run on Ant Range with the same seed learn the same skills (checked: the Range
and North METRA runs of seed 0 log the same median distance and bins at every evaluation), and the
Range figures are the North run's final skills judged by the Range rule. This writes a run folder
`collie report` and `python -m trainer.downstream` read like any other: summary.json with the
coverage figures recomputed (both bin rules), config.json naming the new task, `rescored_from`,
task.json, and the source's eval_latest.npz and checkpoint.pt (so the downstream tasks run with the
new task's safety rule; the Goal task's result, which reads no task, is copied). Only the final
evaluation is rescored; metrics.jsonl's history is not copied. The folder is written under a
hidden name beside it and renamed into place whole: a rescore that fails midway leaves nothing.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np

from collie.tasks import get_task, task_names
from trainer.config import Config
from trainer.envs import env_class
from trainer.methods import METHODS
from trainer.metrics import coverage_metrics
from trainer.report import load_run
from trainer.run_files import (
    RunFolderError,
    folder_written_whole,
    read_arrays,
    read_json_object,
    write_json,
    writing_into,
)
from trainer.sweep import downstream_done, run_downstream_task
from trainer.task_choice import TASK_JSON, choose_rule

CHECKPOINT = "checkpoint.pt"
# Downstream results that do not depend on the run's task, copied from the source: the hierarchical
# Goal task judges flips by the Not-Flip rule whatever the task (trainer/downstream/goal.py).
# Zero-shot motion takes the run's task as its safety rule, so it is run again on the new task.
TASK_FREE_DOWNSTREAM = ("hierarchical",)


class RescoreError(ValueError):
    """The run cannot be judged by another rule (its method reads the task, it is not finished…)."""


def task_free(method: str) -> bool:
    m = METHODS.get(method)
    return m is not None and not m.asks_labels and m.guidance == "one"


def same_run(recorded: str | None, source: Path) -> bool:
    """Whether `recorded` (a `rescored_from`) names `source`: the same path, or the same run folder
    name (a rerun from another directory, or of a moved tree)."""
    if recorded is None:
        return False
    return Path(recorded).resolve() == source.resolve() or Path(recorded).name == source.resolve().name


def rescore(source: Path, task: str, out: Path | None = None, keep_existing: bool = False) -> Path:
    """Write `source`'s final evaluation judged by `task` into `out` (default: the sweep's folder
    name for it, beside `source`); returns the folder. `keep_existing`: a folder already rescored
    from `source` is left as it is (so a bench can be rerun to continue)."""
    summary_path = source / "summary.json"
    if not source.is_dir():
        raise RescoreError(f"{source} is not a folder: give a run folder")
    if not summary_path.exists():
        raise RescoreError(f"{source} is not a run folder: it has no summary.json")
    try:  # names the broken file: a summary or config that is not JSON, or a config without a seed
        summary: dict[str, Any] = load_run(source).metrics
        cfg = dict(summary.get("config") or read_json_object(source / "config.json"))
    except RunFolderError as exc:
        raise RescoreError(str(exc)) from None
    if summary.get("status") != "finished":
        raise RescoreError(f"{source} is not finished (status {summary.get('status')!r})")
    if not task_free(cfg["method"]):
        raise RescoreError(
            f"method {cfg['method']!r} reads its task while it trains (labels or a rule for w); "
            "only METRA, LSD and DIAYN runs can be judged by another task's rule"
        )
    if cfg.get("instruction") or cfg.get("task_file"):
        raise RescoreError(f"{source} was judged by an instruction or a task file, not a built-in task")
    saved = source / "eval_latest.npz"
    if not saved.exists():
        raise RescoreError(f"{source} has no eval_latest.npz (its final skills were not saved)")
    rule = get_task(task, cfg["env"], layout_seed=int(cfg["seed"]))  # fails with the valid task names
    if task == cfg["task"]:
        raise RescoreError(f"{source} is judged by {task} already (its summary.json holds those figures)")
    out = out or source.parent / f"{cfg['env']}-{task}-{cfg['method']}-s{cfg['seed']}"
    if out.exists() and not out.is_dir():  # else mkdir's FileExistsError, a traceback
        raise RescoreError(f"{out} is a file, not a folder")
    if source.resolve() in out.resolve().parents:  # a run inside the run it was made of (itself: "holds a run")
        raise RescoreError(f"--out {out} is inside the run folder {source}; give a folder outside it")
    if (out / "summary.json").exists():
        held = read_json_object(out / "summary.json")  # RunFolderError, a ValueError, names a broken one
        if keep_existing and same_run(held.get("rescored_from"), source):
            return out
        again = " (--keep-existing leaves one rescored from this run as it is)" if not keep_existing else ""
        raise RescoreError(f"{out} already holds a run (summary.json); remove it first{again}")
    if out.is_dir() and any(out.iterdir()):  # the new folder is renamed over it: only an empty one can be
        raise RescoreError(f"{out} holds files but no run (no summary.json); remove it or give another --out")
    arrays = read_arrays(saved, ("xy", "pitch"))  # RunFolderError, a ValueError, names a damaged one
    xy, pitch = list(arrays["xy"].astype(np.float64)), list(arrays["pitch"].astype(np.float64))
    cfg.update(task=task)
    config, env = Config.from_stored(cfg), env_class(cfg["env"])
    figures = coverage_metrics(
        xy, pitch, rule, bin_size=env.metric_bin_size, position_dims=env.position_dims, bin_rule=config.bin_rule
    )
    with writing_into(out), folder_written_whole(out) as new:  # a failure midway leaves no half of it
        shutil.copyfile(saved, new / "eval_latest.npz")
        if (source / CHECKPOINT).exists():
            shutil.copyfile(source / CHECKPOINT, new / CHECKPOINT)
        write_json(new / "config.json", cfg)
        if (source / "downstream.json").exists():
            done = read_json_object(source / "downstream.json")
            kept_results = {k: v for k, v in done.items() if k in TASK_FREE_DOWNSTREAM}
            if kept_results:
                write_json(new / "downstream.json", kept_results)
        write_json(new / TASK_JSON, choose_rule(config).to_json())
        kept = {k: v for k, v in summary.items() if k != "wall_s"}  # no training time was spent on this task
        rescored = {
            **kept,
            **{k: float(v) for k, v in figures.items()},
            "config": cfg,
            "rescored_from": str(source.absolute()),
        }
        write_json(new / "summary.json", rescored)
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("runs", nargs="+", help="finished run folders of METRA, LSD or DIAYN")
    p.add_argument("--task", required=True, help="the built-in task whose rule judges them")
    p.add_argument("--out", default=None, help="output folder (one run only; default: beside each run)")
    p.add_argument(
        "--keep-existing", action="store_true", help="leave a folder already rescored from the same run as it is"
    )
    p.add_argument(
        "--downstream", action="store_true", help="then run the downstream task (unless downstream.json has it)"
    )


def run(args: argparse.Namespace) -> int:
    if args.out and len(args.runs) > 1:
        print("collie rescore: error: --out takes one run", file=sys.stderr)
        return 2
    if args.out and Path(args.out).exists() and not Path(args.out).is_dir():  # as archive and report say it
        print(f"collie rescore: error: --out {args.out} is a file, not a folder", file=sys.stderr)
        return 2
    if args.task not in task_names():  # once, not for each run
        print(
            f"collie rescore: error: unknown task {args.task!r}; valid tasks: {', '.join(task_names())}",
            file=sys.stderr,
        )
        return 2
    refused = 0  # each run is judged on its own, as `collie archive` goes on past a refused run
    for source in args.runs:
        try:
            out = rescore(Path(source), args.task, Path(args.out) if args.out else None, args.keep_existing)
        except (ValueError, KeyError) as exc:  # RescoreError, or an unknown task
            said = str(exc) if source in str(exc) else f"{source}: {exc}"  # which run, among several
            print(f"collie rescore: error: {said}", file=sys.stderr)
            refused += 1
            continue
        print(f"{source} judged by {args.task}: {out}")
        if args.downstream and not downstream_done(out):
            if not (out / CHECKPOINT).exists():
                print(f"collie rescore: error: {source} has no {CHECKPOINT}; no downstream task", file=sys.stderr)
                refused += 1
                continue
            try:
                run_downstream_task(out)  # as `collie sweep --downstream` runs it
            except RuntimeError as exc:
                print(f"collie rescore: error: {source}: the downstream task {exc}", file=sys.stderr)
                refused += 1
                continue
            print(f"  downstream task: {out / 'downstream.json'}")
    return 2 if refused else 0
