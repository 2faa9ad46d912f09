"""`python -m trainer.downstream RUN_DIR`: the downstream task that fits the run's env, written to
RUN_DIR/downstream.json (merged with what is already there; `collie report` reads it).

    planar envs (ant, point)   zero-shot motion with the run's task as the safety rule
    half_cheetah               hierarchical Goal: PPO over the 16 frozen skills
The PPO budget follows the run's preset (`paper` = Table 7; `cpu`, `smoke` are reduced) unless
flags override it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from trainer.downstream.goal import GoalOptions
from trainer.downstream.ppo import PpoConfig, evaluate, greedy, train_ppo
from trainer.downstream.zero_shot import zero_shot
from trainer.memory_plan import NotEnoughMemory, refusal_status
from trainer.pretrained import TrainedSkills, load_skills
from trainer.run_files import RunFolderError, has_checkpoint, read_json_object, write_json
from trainer.task_choice import judged_by

PPO_PRESETS: dict[str, dict[str, Any]] = {
    "paper": {},
    "cpu": dict(iterations=150, hidden=256, lr=3e-4),
    "smoke": dict(iterations=2, hidden=32, update_epochs=2),
}
KINDS = ("auto", "zero_shot", "hierarchical")


def pick_kind(skills: TrainedSkills) -> str:
    return "hierarchical" if skills.prior.discrete else "zero_shot"


def hierarchical(skills: TrainedSkills, ppo: PpoConfig, seed: int, episodes: int = 48) -> dict[str, Any]:
    """Train the PPO controller, then the mean return of its greedy choices (and of random ones)."""
    env = GoalOptions(skills, ppo.envs)
    net, curve = train_ppo(env, ppo, seed=seed)
    trained = evaluate(env, greedy(net), episodes, seed=10_000 + seed)
    rng = np.random.default_rng(seed)
    random_choice = evaluate(env, lambda o: rng.integers(0, env.n_skills, size=len(o)), episodes, 10_000 + seed)
    env.close()
    return {
        "mean": float(trained.mean()),
        "std": float(trained.std()),
        "episodes": episodes,
        "random_skills_mean": float(random_choice.mean()),
        "train_curve": [round(c, 3) for c in curve],
        "ppo": dataclasses.asdict(ppo),
        "epoch": skills.epoch,
    }


def run_downstream(
    run_dir: str | Path,
    kind: str = "auto",
    trajectories: int = 160,
    seed: int = 0,
    ppo_overrides: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Evaluate one finished run; returns and stores {kind: results} in RUN_DIR/downstream.json."""
    run_dir = Path(run_dir)
    skills = load_skills(run_dir)
    kind = pick_kind(skills) if kind == "auto" else kind
    t0 = time.perf_counter()
    if kind == "zero_shot":
        cfg = skills.cfg
        task = judged_by(run_dir, cfg.env, cfg.task, cfg.seed)  # a task file's rule is in the run folder
        if task is None:
            raise ValueError(f"{run_dir} was guided by an instruction alone: zero-shot motion needs a rule for safety")
        result = zero_shot(skills, task, trajectories=trajectories, seed=seed)
    elif kind == "hierarchical":
        values = {**PPO_PRESETS.get(skills.cfg.preset, {}), **(ppo_overrides or {})}
        result = hierarchical(skills, PpoConfig(**values), seed)
    else:
        raise ValueError(f"unknown downstream kind {kind!r}; valid: {', '.join(KINDS)}")
    result["wall_s"] = round(time.perf_counter() - t0, 2)
    path = run_dir / "downstream.json"
    stored = json.loads(path.read_text()) if path.exists() else {}
    stored[kind] = result
    write_json(path, stored)
    return {kind: result}


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The command's flags; also how `collie sweep --downstream-flags` checks its flags up front."""
    p.add_argument("run_dir")
    p.add_argument("--kind", default="auto", choices=KINDS)
    p.add_argument("--trajectories", type=int, default=160, help="zero-shot: skills sampled")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    for f in dataclasses.fields(PpoConfig):
        p.add_argument(
            "--ppo-" + f.name.replace("_", "-"),
            dest=f"ppo_{f.name}",
            default=None,
            type=type(f.default),
            help=f"PPO {f.name} (default: by the run's preset)",
        )


def refusal(a: argparse.Namespace) -> str | None:
    """What is wrong with parsed flags that parsing lets through."""
    return f"--trajectories must be ≥ 1, got {a.trajectories}" if a.trajectories < 1 else None


def not_finished(run_dir: Path) -> str | None:
    """Words for a run that stopped short (its skills are its last checkpoint's), else None."""
    if not (run_dir / "summary.json").exists():  # still training, or killed: no summary yet
        why = "no summary.json: still training, or stopped without one"
        if not has_checkpoint(run_dir):
            return None  # no run here: load_skills says what is missing
    else:
        try:
            summary = read_json_object(run_dir / "summary.json")
        except RunFolderError:  # broken: load_skills names what it needs
            return None
        if summary.get("status") == "finished":
            return None
        why = f"status {summary.get('status')}, epoch {summary.get('epochs_done')}"
    return f"{run_dir} has not finished ({why}): its skills are those of its last checkpoint"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m trainer.downstream", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_arguments(p)
    a = p.parse_args(argv)
    if refusal(a):
        p.error(str(refusal(a)))
    unfinished = not_finished(Path(a.run_dir))
    if unfinished:
        print(f"downstream: warning: {unfinished}", file=sys.stderr)
    torch.set_num_threads(a.threads)
    overrides = {
        f.name: getattr(a, f"ppo_{f.name}")
        for f in dataclasses.fields(PpoConfig)
        if getattr(a, f"ppo_{f.name}") is not None
    }
    try:
        result = run_downstream(a.run_dir, a.kind, a.trajectories, a.seed, overrides)
    except (ValueError, FileNotFoundError) as exc:
        print(f"downstream: error: {exc}", file=sys.stderr)
        return 2
    except NotEnoughMemory as exc:  # the evaluation's envs; 75 where other runs' promises are why (a sweep waits)
        print(f"downstream: error: this machine has not enough memory ({exc})", file=sys.stderr)
        return refusal_status(exc)
    for kind, r in result.items():
        print(json.dumps({"kind": kind, **{k: v for k, v in r.items() if k not in ("train_curve", "ppo")}}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
