"""make bench-update: the cost of COLLIE's gradient step and of vectorised rollouts, as ratios
measured in one run (machines are noisy; absolute numbers are printed for context only).

1. Gradient steps/s of the full paper-size update (φ + λ + SAC + w with 800 labelled states,
   2×1024 MLPs, batch 256) beside a plain SAC update of the same networks. Goal: ≤ 1.3× SAC's cost.
2. Rollout env steps/s (8 episodes stepped together, one policy call per step, paper-size policy)
   beside the raw env step rate of the same env. Goal: ≥ 70 %.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np
import torch

from trainer.config import make_config
from trainer.envs import VectorEnv, raw_step_rate
from trainer.guidance import LabelledSets, guidance_weight
from trainer.metra import Metra, TorchBatch
from trainer.rollout import Normaliser, rollout
from trainer.skills import SkillPrior


def timed(fn: Callable[[], None], steps: int) -> float:
    start = time.perf_counter()
    for _ in range(steps):
        fn()
    return steps / (time.perf_counter() - start)


def bench_update(env_name: str, steps: int, rounds: int) -> dict[str, float]:
    env = VectorEnv(env_name, 1)
    cfg = make_config("paper", env_name)
    dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    prior = SkillPrior(cfg.skill_dim, cfg.discrete_skills)
    agent = Metra(env.obs_dim, env.action_dim, prior, cfg, dev)
    rng = np.random.default_rng(0)
    b = cfg.batch_size

    def batch() -> TorchBatch:
        z = torch.as_tensor(prior.sample(b, rng), device=dev)
        obs = torch.randn(b, env.obs_dim, device=dev)
        return TorchBatch(
            obs,
            obs + 0.1 * torch.randn_like(obs),
            torch.rand(b, env.action_dim, device=dev) * 2 - 1,
            z,
            torch.as_tensor(prior.reward_direction(z.cpu().numpy()), device=dev),
        )

    labelled = LabelledSets(lambda x: x, dev)
    for q in range(40):  # N_total = 40 segments × H = 20 states
        labelled.set(f"q{q}", rng.normal(size=(20, env.obs_dim)).astype(np.float32), q % 3)
    batches = [batch() for _ in range(8)]
    it = iter(range(10**9))

    def full() -> None:
        def w(_s: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
            return guidance_weight(n, labelled.embeddings(agent.phi, agent.phi_version))

        agent.update(batches[next(it) % 8], w)

    def plain_sac() -> None:
        agent.sac_update(batches[next(it) % 8], torch.randn(b, device=dev))

    timed(full, 3), timed(plain_sac, 3)  # warm-up
    full_rates, sac_rates = [], []
    for _ in range(rounds):  # interleaved, so both see the same machine load
        full_rates.append(timed(full, steps))
        sac_rates.append(timed(plain_sac, steps))
    full_r, sac_r = float(np.median(full_rates)), float(np.median(sac_rates))
    return {"full_steps_per_s": full_r, "sac_steps_per_s": sac_r, "cost_ratio": sac_r / full_r}


def bench_rollout(env_name: str, rounds: int) -> dict[str, float]:
    cfg = make_config("paper", env_name)
    env = VectorEnv(env_name, cfg.episodes_per_epoch)
    prior = SkillPrior(cfg.skill_dim, cfg.discrete_skills)
    agent = Metra(env.obs_dim, env.action_dim, prior, cfg, torch.device("cpu"))
    norm = Normaliser(env.obs_mean, env.obs_std)
    rng = np.random.default_rng(0)
    roll, raw = [], []
    for r in range(rounds):
        skills = prior.sample(env.num_envs, rng)
        start = time.perf_counter()
        rollout(env, agent, skills, list(range(r * 8, r * 8 + 8)), norm, deterministic=False)
        roll.append(env.num_envs * env.episode_steps / (time.perf_counter() - start))
        raw.append(raw_step_rate(env_name, steps=env.num_envs * env.episode_steps, seed=r))
    roll_r, raw_r = float(np.median(roll)), float(np.median(raw))
    return {"rollout_steps_per_s": roll_r, "raw_steps_per_s": raw_r, "rollout_fraction": roll_r / raw_r}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="ant")
    p.add_argument("--steps", type=int, default=10, help="gradient steps per timed block")
    p.add_argument("--rounds", type=int, default=5)
    a = p.parse_args()
    print(
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, "
        f"device {'cuda' if torch.cuda.is_available() else 'cpu'}"
    )
    u = bench_update(a.env, a.steps, a.rounds)
    print(f"update  ({a.env}, 2×1024, batch 256, 800 labelled states)")
    print(f"  full COLLIE step  {u['full_steps_per_s']:8.1f} steps/s")
    print(f"  plain SAC step    {u['sac_steps_per_s']:8.1f} steps/s")
    print(f"  cost ratio        {u['cost_ratio']:8.2f}×   (goal ≤ 1.30×)")
    r = bench_rollout(a.env, a.rounds)
    print(f"rollout ({a.env}, 8 episodes × 200 steps, paper-size policy)")
    print(f"  vectorised rollout {r['rollout_steps_per_s']:8.0f} env steps/s")
    print(f"  raw env stepping   {r['raw_steps_per_s']:8.0f} env steps/s")
    print(f"  fraction           {100 * r['rollout_fraction']:8.0f} %   (goal ≥ 70 %)")
    print(json.dumps({"env": a.env, **u, **r}))


if __name__ == "__main__":
    main()
