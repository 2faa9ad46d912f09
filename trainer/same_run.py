"""Whether two run folders hold the same run: their configs compared without where the folder was
and how the run used the machine. Shared by `collie report` (which runs may share a cell),
`collie archive` (which run may refresh an archived one) and `collie sweep` (which finished run
its command would make again)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from trainer.config import FIRST_VERSION, Config, first_version, make_config
from trainer.run_files import read_json_object

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


def comparable(cfg: dict[str, Any]) -> dict[str, Any]:
    """`cfg` as this version reads it, without NOT_THE_RUN: a key it lacks takes the value the run
    had (`Config.from_stored`: an option the run predates) or else its preset's; unknown keys dropped."""
    preset = {k: v for k, v in preset_defaults(cfg).items() if k not in FIRST_VERSION}
    full = Config.from_stored({**preset, **first_version(cfg), **cfg}).to_dict()  # dated by cfg's own keys
    return {k: v for k, v in full.items() if k not in NOT_THE_RUN}


def differing_keys(a: dict[str, Any], b: dict[str, Any], besides: tuple[str, ...] = ()) -> list[str]:
    """The config keys whose values differ between `a` and `b`, NOT_THE_RUN and `besides` aside
    (("epochs",): more of them extend a run, a resumed one included), sorted."""
    ca, cb = comparable(a), comparable(b)
    return sorted(k for k in ca.keys() | cb.keys() if ca.get(k) != cb.get(k) and k not in besides)


def preset_defaults(cfg: dict[str, Any]) -> dict[str, Any]:
    """What `cfg`'s preset gives its env when no flag is given ({} for a preset or env this version
    does not know: every value then counts as given)."""
    try:
        return make_config(str(cfg.get("preset", Config.preset)), str(cfg.get("env", Config.env))).to_dict()
    except ValueError:
        return {}


def run_config(folder: Path) -> dict[str, Any]:
    """The config a run folder holds: summary.json's, else config.json's ({} if neither has one);
    RunFolderError naming a file that cannot be read."""
    config = read_json_object(folder / "summary.json").get("config")
    if isinstance(config, dict):
        return config
    return read_json_object(folder / "config.json") if (folder / "config.json").exists() else {}
