"""The raw speed of one env, the yardstick for the trainer's rollout-rate benchmark."""

from __future__ import annotations

import time

import numpy as np

from trainer.envs.registry import make_env


def raw_step_rate(name: str, steps: int = 2000, seed: int = 0) -> float:
    """Env steps per second of ONE env stepping uniform random actions through its public
    `step` (resets at each episode end included; action sampling excluded)."""
    env = make_env(name, seed=seed)
    actions = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, env.action_dim))
    env.reset()
    start = time.perf_counter()
    for action in actions:
        truncated = env.step(action)[3]
        if truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed
