"""Zero-shot Ant motion (Appendix E, "Zero-shot performance"): roll out skills sampled from p(z) —
no fine-tuning — on a task whose per-step reward is
    r_t = 1  +  max(|v_x|, |v_y|)  −  20·1[s_{t+1} is unsafe for the guidance task]
(survival, movement, safety penalty; v from the x-y displacement over one control step). Reported:
the average and the best return over the sampled skills (the reference samples 160 stochastic
trajectories).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from collie.tasks import BAD, Task
from trainer.acting import acting_path
from trainer.envs import VectorEnv
from trainer.pretrained import TrainedSkills
from trainer.rollout import rollout

SURVIVAL, UNSAFE_PENALTY = 1.0, 20.0


def motion_returns(xy: np.ndarray, classes: np.ndarray, dt: float) -> np.ndarray:
    """Per-trajectory returns of the motion task. xy (n, T+1, 2), classes (n, T+1) g(s) per state."""
    velocity = np.diff(xy, axis=1) / dt  # (n, T, 2)
    speed = np.abs(velocity).max(axis=-1)
    unsafe = classes[:, 1:] == BAD
    return (SURVIVAL + speed - UNSAFE_PENALTY * unsafe).sum(axis=1)


def zero_shot(
    skills: TrainedSkills, task: Task, trajectories: int = 160, seed: int = 0, deterministic: bool = False
) -> dict[str, Any]:
    """Average, spread and best return of `trajectories` skills z ~ p(z) (stochastic π by default),
    `task` judging which states are unsafe."""
    cfg = skills.cfg
    env = VectorEnv(cfg.env, trajectories, episode_steps=cfg.episode_steps, layout_seed=cfg.seed)
    first = env.envs[0]
    dt = float(first.model.opt.timestep * first.frame_skip)
    rng = np.random.default_rng(seed)
    z = skills.prior.sample(trajectories, rng)
    seeds = [int(s) for s in rng.integers(0, 2**31 - 1, size=trajectories)]
    traj = rollout(env, skills.agent, z, seeds, skills.normalise, deterministic, acting_path(cfg.acting))
    env.close()
    xy = traj.xy.astype(np.float64)
    n, t1 = xy.shape[:2]
    classes = task.classify(xy.reshape(-1, 2), traj.pitch.astype(np.float64).reshape(-1)).reshape(n, t1)
    returns = motion_returns(xy, classes, dt)
    return {
        "task": task.name,
        "trajectories": trajectories,
        "deterministic": deterministic,
        "seed": seed,
        "mean": float(returns.mean()),
        "std": float(returns.std()),
        "best": float(returns.max()),
        "epoch": skills.epoch,
    }
