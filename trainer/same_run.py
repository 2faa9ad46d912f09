"""Whether two run folders hold the same run: their configs (and a task file's rule) compared
without where the folder was and how the run used the machine. Shared by `collie report` (which
runs may share a cell), `collie archive` (which run may refresh an archived one) and `collie
sweep` (which finished run its command would make again)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from trainer.config import FIRST_VERSION, Config, first_version, make_config
from trainer.run_files import read_json_object
from trainer.task_choice import TASK_JSON

# where a run's folder and task file were, how it used the machine and how often it checkpointed
# (resume is exact: the same metrics to the last digit): a moved, archived or resumed copy of one
# run may differ in these and is still that run
NOT_THE_RUN = (
    "out",
    "task_file",
    "threads",
    "device",
    "compile",
    "fast_ops",
    "fused_adam",
    "flush_denormal",
    "checkpoint_every",
)
# what a report's rows and columns already say (the method, its task and env, the seed)
PLACED = ("env", "task", "method", "seed")
# a task file's run: its rule, as a digest of what the folder's task.json holds. Two files of one
# task name (or one file edited between runs) may judge differently: those runs are not the same.
RULE = "rule"


def rule_digest(definition: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(definition, sort_keys=True).encode()).hexdigest()[:8]


def with_rule(folder: Path, cfg: dict[str, Any]) -> dict[str, Any]:
    """`cfg` with RULE when it is a task file's run whose folder saved the rule (task.json);
    RunFolderError naming a task.json that cannot be read."""
    saved = folder / TASK_JSON
    if not cfg.get("task_file") or not saved.exists():
        return cfg
    definition = read_json_object(saved).get("definition")
    return {**cfg, RULE: rule_digest(definition)} if isinstance(definition, dict) else cfg


def comparable(cfg: dict[str, Any]) -> dict[str, Any]:
    """`cfg` as this version reads it, without NOT_THE_RUN: a key it lacks takes the value the run
    had (`Config.from_stored`: an option the run predates) or else its preset's; unknown keys dropped."""
    preset = {k: v for k, v in preset_defaults(cfg).items() if k not in FIRST_VERSION}
    full = Config.from_stored({**preset, **first_version(cfg), **cfg}).to_dict()  # dated by cfg's own keys
    rule = {RULE: cfg[RULE]} if RULE in cfg else {}
    return {k: v for k, v in full.items() if k not in NOT_THE_RUN} | rule


def differing_keys(a: dict[str, Any], b: dict[str, Any], besides: tuple[str, ...] = ()) -> list[str]:
    """The config keys whose values differ between `a` and `b`, NOT_THE_RUN and `besides` aside
    (("epochs",): more of them extend a run, a resumed one included), sorted."""
    ca, cb = comparable(a), comparable(b)
    if RULE not in ca or RULE not in cb:  # a run from before task.json (or a command without a task file)
        ca.pop(RULE, None)
        cb.pop(RULE, None)
    return sorted(k for k in ca.keys() | cb.keys() if ca.get(k) != cb.get(k) and k not in besides)


def only_more_epochs(keys: list[str], made: dict[str, Any], asked: dict[str, Any]) -> bool:
    """The differing `keys` of two comparable configs say `asked` is `made` with more epochs: the
    same run extended (`collie train --resume --epochs N` takes only them; its config wins)."""
    return keys == ["epochs"] and asked["epochs"] > made["epochs"]


def preset_defaults(cfg: dict[str, Any]) -> dict[str, Any]:
    """What `cfg`'s preset gives its env when no flag is given ({} for a preset or env this version
    does not know: every value then counts as given)."""
    try:
        return make_config(str(cfg.get("preset", Config.preset)), str(cfg.get("env", Config.env))).to_dict()
    except ValueError:
        return {}


def run_config(folder: Path) -> dict[str, Any]:
    """The config a run folder holds: summary.json's, else config.json's ({} if neither has one),
    with its task file's RULE; RunFolderError naming a file that cannot be read."""
    summary = folder / "summary.json"
    config = read_json_object(summary).get("config") if summary.exists() else None
    if not isinstance(config, dict):
        config = read_json_object(folder / "config.json") if (folder / "config.json").exists() else {}
    return with_rule(folder, config)
