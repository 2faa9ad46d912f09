"""Collecting trajectories: all episodes of an epoch step together and the policy runs once per
step for the whole batch (Algorithm 1, line 3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from trainer.envs import StepBatch, VectorEnv
from trainer.metra import Metra


@dataclass
class Trajectories:
    obs: np.ndarray  # (n, T+1, *obs_shape) raw
    action: np.ndarray  # (n, T, |A|)
    skill: np.ndarray  # (n, k)
    xy: np.ndarray  # (n, T+1, 2)
    pitch: np.ndarray  # (n, T+1)
    qpos: np.ndarray  # (n, T+1, nq)
    qvel: np.ndarray  # (n, T+1, nv)


class Normaliser:
    """Fixed per-dimension statistics of the env (as the reference METRA): (s − μ) / σ. Pixel envs
    give scalars (0, 255): images are only scaled to [0, 1]."""

    def __init__(self, mean: np.ndarray, std: np.ndarray) -> None:
        self.mean = np.asarray(mean, np.float32)
        self.std = np.asarray(std, np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return (obs - self.mean) / self.std


def rollout(
    env: VectorEnv, agent: Metra, skills: np.ndarray, seeds: list[int], normalise: Normaliser, deterministic: bool
) -> Trajectories:
    """Run one episode per env with skill `skills[i]`; returns the full trajectories."""
    n, t_max = env.num_envs, env.episode_steps
    if skills.shape[0] != n:
        raise ValueError(f"need {n} skills, got {skills.shape[0]}")
    obs = np.zeros((n, t_max + 1, *env.obs_shape), env.obs_dtype)
    action = np.zeros((n, t_max, env.action_dim), np.float32)
    xy = np.zeros((n, t_max + 1, 2), np.float32)
    pitch = np.zeros((n, t_max + 1), np.float32)
    qpos = np.zeros((n, t_max + 1, env.nq), np.float32)
    qvel = np.zeros((n, t_max + 1, env.nv), np.float32)

    def store(t: int, b: StepBatch) -> None:
        obs[:, t], xy[:, t], pitch[:, t], qpos[:, t], qvel[:, t] = b.obs, b.xy, b.pitch, b.qpos, b.qvel

    store(0, env.reset(seeds))
    z = torch.as_tensor(skills, dtype=torch.float32, device=agent.device)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # batch-of-8 forwards: extra threads only add sync cost (10–80× on a busy CPU)
    try:
        for t in range(t_max):
            o = torch.as_tensor(normalise(obs[:, t]), device=agent.device)
            a = agent.act(o, z, deterministic).cpu().numpy()
            action[:, t] = a
            store(t + 1, env.step(a))
    finally:
        torch.set_num_threads(threads)
    return Trajectories(obs, action, skills.astype(np.float32), xy, pitch, qpos, qvel)
