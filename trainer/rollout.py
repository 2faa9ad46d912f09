"""Collecting trajectories: all episodes of an epoch step together (Algorithm 1, line 3).

Each step the policy acts for every env (trainer/acting.py: the policy's forward in a few torch
calls) and the VectorEnv steps them, writing straight into the trajectory arrays. Plain envs
(Ant, HalfCheetah, point) step as one mujoco.batch call spread over the physics threads. For the
other state envs with more than one physics thread the loop is a pipeline: the policy acts for
group g while the physics of the other groups runs in C on the worker threads (mj_step releases
the GIL). Each env's trajectory depends only on its seed and its own actions, so neither changes
an observation; the policy's noise is drawn per call, in a fixed order, so a run stays
deterministic per seed."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass

import numpy as np
import torch

from trainer.acting import Acting, actor
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
    env: VectorEnv,
    agent: Metra,
    skills: np.ndarray,
    seeds: list[int],
    normalise: Normaliser,
    deterministic: bool,
    acting: Callable[[Metra, np.ndarray, Normaliser, bool], Acting] = actor,
) -> Trajectories:
    """Run one episode per env with skill `skills[i]`; returns the full trajectories. `acting` builds
    the policy's path (trainer/acting.py; benchmarks pass TorchActor to compare)."""
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
    policy = acting(agent, skills, normalise, deterministic)

    def act(rows: slice, t: int) -> np.ndarray:
        policy(obs[rows, t], rows, action[rows, t])
        return action[rows, t]

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # batch-of-8 forwards: extra threads only add sync cost (10–80× on a busy CPU)
    try:
        if isinstance(env, VectorEnv) and env.pipelined:
            views = [StepBatch(obs[:, t], xy[:, t], pitch[:, t], qpos[:, t], qvel[:, t]) for t in range(t_max + 1)]
            pending: list[Future | None] = [None] * len(env.groups)
            try:
                for t in range(t_max):
                    for g, rows in enumerate(env.groups):
                        waiting = pending[g]
                        if waiting is not None:
                            waiting.result()  # group g's state at t is in `obs`
                        pending[g] = env.submit(env.step_rows, rows, act(rows, t), views[t + 1])
            finally:
                for f in pending:
                    if f is not None:
                        f.result()
        else:  # batched physics (its own threads), pixel envs, wrappers such as NoisyObservations
            every = slice(None)
            for t in range(t_max):  # `out` writes into the trajectory; store() copies what a wrapper replaced
                out = StepBatch(obs[:, t + 1], xy[:, t + 1], pitch[:, t + 1], qpos[:, t + 1], qvel[:, t + 1])
                store(t + 1, env.step(act(every, t), out=out))
    finally:
        torch.set_num_threads(threads)
    return Trajectories(obs, action, skills.astype(np.float32), xy, pitch, qpos, qvel)
