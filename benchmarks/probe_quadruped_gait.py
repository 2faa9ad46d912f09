"""make probe-quadruped-gait: can the pixel Quadruped walk at all? (docs/results.md, the pixel Quadruped)

How far the robot's root travels in one 200-step episode from the initial state of each seed under
three open-loop action sequences: a fixed sine gait (`sin(0.5 t + i)` on actuator i), zero actions
(it only settles after the drop), and uniform random actions in [-1, 1] from
`np.random.default_rng(seed)`. A gait that goes far while trained skills stay near the start says
the learner, not the robot, is what holds the skills still. No torch, no training: seconds.

    python benchmarks/probe_quadruped_gait.py --seeds 4

JSON (runs/bench/quadruped_gait.json): seeds, and per sequence (gait, still, random) the list of
distances in env units, one per seed.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np
from record import record

from trainer.envs import make_env
from trainer.envs.quadruped import QuadrupedEnv


def distance_after(env: QuadrupedEnv, seed: int, action_at: Callable[[int], np.ndarray]) -> float:
    """The root's x-y distance from its start after one episode of open-loop actions."""
    env.reset(seed=seed)
    start = env.data.qpos[:2].copy()
    for t in range(env.episode_steps):
        env.step(action_at(t))
    return float(np.linalg.norm(env.data.qpos[:2] - start))


def uniform_actions(rng: np.random.Generator, dim: int) -> Callable[[int], np.ndarray]:
    """Fresh uniform actions in [-1, 1] at every step, from the seed's own generator."""
    return lambda t: rng.uniform(-1.0, 1.0, dim)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=4, help="initial states of seeds 0 … N−1")
    args = p.parse_args()
    if args.seeds < 1:
        p.error(f"--seeds must be ≥ 1, got {args.seeds}")
    env = make_env("quadruped", seed=0)
    assert isinstance(env, QuadrupedEnv)
    phases = np.arange(env.action_dim)
    figures: dict[str, list[float]] = {"gait": [], "still": [], "random": []}
    for seed in range(args.seeds):
        sequences: dict[str, Callable[[int], np.ndarray]] = {
            "gait": lambda t: np.sin(0.5 * t + phases),
            "still": lambda t: np.zeros(env.action_dim),
            "random": uniform_actions(np.random.default_rng(seed), env.action_dim),
        }
        for name, action_at in sequences.items():
            figures[name].append(round(distance_after(env, seed, action_at), 2))
        print(f"seed {seed}: " + ", ".join(f"{k} {v[-1]:.2f}" for k, v in figures.items()), flush=True)
    env.close()
    record("quadruped_gait", {"seeds": args.seeds, **figures})


if __name__ == "__main__":
    main()
