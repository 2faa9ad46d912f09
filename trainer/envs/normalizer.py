"""Fixed per-dimension observation statistics (obs_mean, obs_std), as METRA normalises φ's input.

Each env class stores its statistics as constants, so every run normalises identically and no
statistic drifts with training. For `ant` and `half_cheetah` they are the mean and standard
deviation over all states of random-action rollouts (uniform actions in [-1, 1], episodes of
200 steps, env seeds 0 … episodes−1, reset states included), std floored at STD_FLOOR so that
near-constant dimensions do not blow up. Regenerate and paste into the env module with:

    python -m trainer.envs.normalizer --env ant [--episodes 100]

`point`'s statistics are chosen by hand (see trainer/envs/point.py for why); the command still
prints its random-rollout statistics for comparison.
"""

from __future__ import annotations

import argparse
import textwrap

import numpy as np

from trainer.envs.registry import ENV_NAMES, make_env

STD_FLOOR = 1e-3


def random_rollout_stats(name: str, episodes: int = 100, episode_steps: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """(mean, std) of every observation seen in `episodes` random-action episodes."""
    env = make_env(name, episode_steps=episode_steps)
    rng = np.random.default_rng(0)
    states = np.empty((episodes, episode_steps + 1, env.obs_dim))
    for ep in range(episodes):
        states[ep, 0] = env.reset(seed=ep)[0]
        for t in range(episode_steps):
            states[ep, t + 1] = env.step(rng.uniform(-1.0, 1.0, env.action_dim))[0]
    env.close()
    flat = states.reshape(-1, env.obs_dim)
    return flat.mean(axis=0), np.maximum(flat.std(axis=0), STD_FLOOR)


def _literal(name: str, values: np.ndarray) -> str:
    """`name = np.array([...])` wrapped to fit the project's line length, ready to paste."""
    body = textwrap.fill(
        ", ".join(f"{v:.4g}" for v in values), width=96, initial_indent=" " * 4, subsequent_indent=" " * 4
    )
    return f"{name} = np.array([\n{body},\n], dtype=np.float32)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", required=True, choices=ENV_NAMES)
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    mean, std = random_rollout_stats(args.env, args.episodes)
    print(_literal("obs_mean", mean))
    print(_literal("obs_std", std))


if __name__ == "__main__":
    main()
