"""Lockstep stepping of n copies of one env for the trainer's rollouts.

All episodes have the same length and never end early, so there is no auto-reset: the trainer
resets every env at the start of an epoch with seeds it chooses, which makes rollouts
reproducible (same seeds and actions ⇒ same observations). Stepping writes straight into the
batch arrays, avoiding Gymnasium's vector wrappers and per-step info dicts.

The envs form `physics_threads` groups. `mj_step` releases the GIL, so `step_rows` may run for
disjoint groups in the worker threads of `submit`: the trainer's rollout steps one group's
physics while the policy acts for the next (trainer/rollout.py). Plain envs
(`SkillEnv.batched_physics`: Ant, HalfCheetah, point) step a group as one `mujoco.batch` call
(trainer/envs/batched.py), bit-identical to stepping each env; the others loop over the group's
envs in Python. Each env has its own state, so the result does not depend on the order or the
threads. Pixel envs render through one shared GL context and stay on one thread.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from trainer.envs.base import SkillEnv
from trainer.envs.batched import BatchedPhysics
from trainer.envs.registry import make_env
from trainer.memory_ledger import check_beside_others
from trainer.memory_plan import ENVS_MEASURED, PROJECTED_SHARE, resident_bytes


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


# The default: one group, whose `mujoco.batch` call spreads its envs over 2 MuJoCo threads (the
# policy needs the rest of a 2-core machine). Measured on 2 quiet cores (`make bench-update`,
# docs/results.md): HalfCheetah 68 % of a raw mj_step loop serial, 59 % pipelined, 97 % so; Ant
# 71 % serial, 96 % pipelined, 110 % so. Bit-identical at any count (tests/core/test_overlap.py).
DEFAULT_BATCH_THREADS = 2


def make_envs(name: str, num_envs: int, episode_steps: int, layout_seed: int | None) -> list[SkillEnv]:
    """`num_envs` envs (each its own MuJoCo model and data). The rest are projected from the memory
    the ENVS_MEASURED after the first took, and refused (NotEnoughMemory) where they would not fit:
    the kernel would kill the process only once it had made them, which for 100 000 takes minutes."""
    envs = [make_env(name, episode_steps=episode_steps, layout_seed=layout_seed)]
    before = resident_bytes()  # after the first: its one-time costs (e.g. a GL context) are not projected
    for i in range(1, num_envs):
        envs.append(make_env(name, episode_steps=episode_steps, layout_seed=layout_seed))
        now = resident_bytes() if i == ENVS_MEASURED and i + 1 < num_envs else None
        if before is not None and now is not None:
            each = PROJECTED_SHARE * max(0, now - before) / ENVS_MEASURED
            check_beside_others(f"{num_envs} {name} envs", int(each * (num_envs - i - 1)))
    return envs


def default_batch_threads(num_envs: int) -> int:
    return max(1, min(DEFAULT_BATCH_THREADS, os.cpu_count() or 1, num_envs))


class VectorEnv:
    def __init__(
        self,
        name: str,
        num_envs: int,
        episode_steps: int = 200,
        layout_seed: int | None = None,
        physics_threads: int | None = None,
        batch_threads: int | None = None,
    ) -> None:
        """`physics_threads`: groups of envs stepped in parallel by `rollout`, each by a worker
        thread overlapping the policy (None or 1 = one group, serial, as `step`; pixel envs are
        always serial). `batch_threads`: MuJoCo threads within each group's `mujoco.batch` call
        (envs with batched physics only; None = the default above, 1 = the calling thread)."""
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        if physics_threads is not None and physics_threads < 1:
            raise ValueError(f"physics_threads must be >= 1, got {physics_threads}")
        if batch_threads is None:
            batch_threads = default_batch_threads(num_envs) if (physics_threads or 1) == 1 else 1
        if batch_threads < 1:
            raise ValueError(f"batch_threads must be >= 1, got {batch_threads}")
        self.envs = make_envs(name, num_envs, episode_steps, layout_seed)
        first = self.envs[0]
        self.name = name
        self.num_envs = num_envs
        self.episode_steps = episode_steps
        self.obs_dim, self.action_dim = first.obs_dim, first.action_dim
        self.obs_shape, self.obs_dtype = first.obs_shape, first.obs_dtype
        self.metric_bin_size = first.metric_bin_size
        self.position_dims, self.nq, self.nv = first.position_dims, first.nq, first.nv
        self.obs_mean, self.obs_std = first.obs_mean, first.obs_std
        pixels = len(self.obs_shape) > 1
        self.physics_threads = 1 if pixels else min(physics_threads or 1, num_envs)
        bounds = np.linspace(0, num_envs, self.physics_threads + 1).round().astype(int)
        self.groups = [slice(int(a), int(b)) for a, b in itertools.pairwise(bounds)]
        self._pool: ThreadPoolExecutor | None = None
        # one batch per group holds the state between resets; the envs draw each reset
        batched = first.batched_physics and not pixels
        self._physics = [BatchedPhysics(self.envs[g], g, batch_threads) for g in self.groups] if batched else None
        self.batch_threads = self._physics[0].batch.nthread if self._physics else 1

    @property
    def pipelined(self) -> bool:
        """True when the rollout should overlap the groups' `step_rows` with the policy."""
        return self.physics_threads > 1

    @property
    def t(self) -> int:
        """Steps taken in the current episodes; -1 before the first reset."""
        return self._physics[0].t if self._physics is not None else self.envs[0].t

    @property
    def truncated(self) -> bool:
        return self.t >= self.episode_steps

    def reset(self, seeds: Sequence[int]) -> StepBatch:
        if len(seeds) != self.num_envs:
            raise ValueError(f"need {self.num_envs} seeds, got {len(seeds)}")
        for env, seed in zip(self.envs, seeds, strict=True):
            env.reset(seed=int(seed))
        if self._physics is not None:
            for group in self._physics:
                group.load()
        return self._collect(None)

    def step(self, actions: np.ndarray, out: StepBatch | None = None) -> StepBatch:
        """Step every env once. Pass `out` to reuse its arrays (then earlier results are overwritten)."""
        if actions.shape != (self.num_envs, self.action_dim):
            expected = (self.num_envs, self.action_dim)
            raise ValueError(f"actions must have shape {expected}, got {actions.shape}")
        b = out if out is not None else self._empty()
        for rows in self.groups:
            self.step_rows(rows, actions[rows], b)
        return b

    def step_rows(self, rows: slice, actions: np.ndarray, out: StepBatch) -> None:
        """Step the envs `rows` once with `actions` (one row each) and write their new state into
        the same rows of `out`. `rows` is one of `groups`; different groups may step in parallel
        (see the module docstring)."""
        if self._physics is None:
            for env, action in zip(self.envs[rows], actions, strict=True):
                env.advance(action)
            self._collect(out, rows)
            return
        group = self._physics[self.groups.index(rows)]
        group.step(actions)
        group.collect(out)

    def submit(self, fn: Callable[..., None], *args: object) -> Future:
        """Run fn(*args) on one of `physics_threads` worker threads."""
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self.physics_threads, thread_name_prefix=f"physics-{self.name}")
        return self._pool.submit(fn, *args)

    def _empty(self) -> StepBatch:
        return StepBatch.empty(self.num_envs, self.obs_shape, self.nq, self.nv, self.obs_dtype)

    def _collect(self, out: StepBatch | None, rows: slice = slice(None)) -> StepBatch:
        b = out if out is not None else self._empty()
        if self._physics is not None:
            for group in self._physics:
                group.collect(b)
            return b
        for i, env in zip(range(self.num_envs)[rows], self.envs[rows], strict=True):
            env.observe_into(b.obs[i])
            env.xy_into(b.xy[i])
            b.pitch[i] = env.pitch()
            b.qpos[i] = env.data.qpos
            b.qvel[i] = env.data.qvel
        return b

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        for env in self.envs:
            env.close()
