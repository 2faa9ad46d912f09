"""Lockstep stepping of n copies of one env for the trainer's rollouts.

All episodes have the same length and never end early, so there is no auto-reset: the trainer
resets every env at the start of an epoch with seeds it chooses, which makes rollouts
reproducible (same seeds and actions ⇒ same observations). One tight loop over the envs writes
straight into the batch arrays, avoiding Gymnasium's vector wrappers and per-step info dicts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from trainer.envs.base import SkillEnv
from trainer.envs.registry import make_env


@dataclass
class StepBatch:
    """The state of every env after a reset or a step (row i = env i)."""

    obs: np.ndarray  # (n, *obs_shape): float32 vectors, or uint8 frame stacks for pixel envs
    xy: np.ndarray  # (n, 2) float64, y = 0 for 1-D envs
    pitch: np.ndarray  # (n,) float64, nan where undefined
    qpos: np.ndarray  # (n, nq) float64
    qvel: np.ndarray  # (n, nv) float64

    @classmethod
    def empty(
        cls, n: int, obs_shape: int | tuple[int, ...], nq: int, nv: int, obs_dtype: np.dtype | type = np.float32
    ) -> StepBatch:
        shape = (obs_shape,) if isinstance(obs_shape, int) else tuple(obs_shape)
        return cls(
            np.empty((n, *shape), obs_dtype), np.empty((n, 2)), np.empty(n), np.empty((n, nq)), np.empty((n, nv))
        )


class VectorEnv:
    def __init__(self, name: str, num_envs: int, episode_steps: int = 200, layout_seed: int | None = None) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.envs: list[SkillEnv] = [
            make_env(name, episode_steps=episode_steps, layout_seed=layout_seed) for _ in range(num_envs)
        ]
        first = self.envs[0]
        self.name = name
        self.num_envs = num_envs
        self.episode_steps = episode_steps
        self.obs_dim, self.action_dim = first.obs_dim, first.action_dim
        self.obs_shape, self.obs_dtype = first.obs_shape, first.obs_dtype
        self.metric_bin_size = first.metric_bin_size
        self.position_dims, self.nq, self.nv = first.position_dims, first.nq, first.nv
        self.obs_mean, self.obs_std = first.obs_mean, first.obs_std
        self.t = -1  # steps taken in the current episodes; -1 before the first reset

    @property
    def truncated(self) -> bool:
        return self.t >= self.episode_steps

    def reset(self, seeds: Sequence[int]) -> StepBatch:
        if len(seeds) != self.num_envs:
            raise ValueError(f"need {self.num_envs} seeds, got {len(seeds)}")
        for env, seed in zip(self.envs, seeds, strict=True):
            env.reset(seed=int(seed))
        self.t = 0
        return self._collect(None)

    def step(self, actions: np.ndarray, out: StepBatch | None = None) -> StepBatch:
        """Step every env once. Pass `out` to reuse its arrays (then earlier results are overwritten)."""
        if actions.shape != (self.num_envs, self.action_dim):
            expected = (self.num_envs, self.action_dim)
            raise ValueError(f"actions must have shape {expected}, got {actions.shape}")
        for env, action in zip(self.envs, actions, strict=True):
            env.advance(action)
        self.t += 1
        return self._collect(out)

    def _collect(self, out: StepBatch | None) -> StepBatch:
        b = out if out is not None else StepBatch.empty(self.num_envs, self.obs_shape, self.nq, self.nv, self.obs_dtype)
        for i, env in enumerate(self.envs):
            env.observe_into(b.obs[i])
            env.xy_into(b.xy[i])
            b.pitch[i] = env.pitch()
            b.qpos[i] = env.data.qpos
            b.qvel[i] = env.data.qvel
        return b

    def close(self) -> None:
        for env in self.envs:
            env.close()
