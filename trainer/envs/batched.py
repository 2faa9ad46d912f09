"""Many copies of one plain env stepped by MuJoCo's own thread pool (`mujoco.batch.Batch`).

For envs whose observation is [qpos, qvel] and whose step is "ctrl ← action; mj_step × frame_skip"
(`SkillEnv.batched_physics`), a step of all n envs is one C call that releases the GIL and runs on
`threads` threads, and the batch's state is read as (n, ·) arrays: no Python loop per env. The
envs themselves still draw each reset (Gymnasium's reset noise, the same as stepping them one by
one); their whole integration state, warm start included, then moves into the batch, whose steps
are bit-identical to `mj_step` on each env's MjData at any thread count (MuJoCo's guarantee;
tests/core/test_overlap.py checks it against serial stepping).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import mujoco
import numpy as np
from mujoco.batch import Batch

from trainer.envs.base import SkillEnv

if TYPE_CHECKING:
    from trainer.envs.vector import StepBatch

STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # everything mj_step reads, qacc_warmstart included
PLAIN = ("advance", "observe_into", "xy_into")  # SkillEnv's own mechanics, which the batch reproduces


def check_plain(env: SkillEnv) -> None:
    """A batched env must use SkillEnv's own step and observation, as the batch does."""
    for method in PLAIN:
        if getattr(type(env), method) is not getattr(SkillEnv, method):
            raise TypeError(f"{type(env).__name__} overrides {method}; it cannot set batched_physics")


class BatchedPhysics:
    def __init__(self, envs: Sequence[SkillEnv], threads: int) -> None:
        first = envs[0]
        for env in envs:
            check_plain(env)
        self.env_class = type(first)
        self.envs = list(envs)
        self.frame_skip = first.frame_skip
        self.nq, self.position_dims = first.nq, first.position_dims
        self.batch = Batch(first.model, len(envs), nthread=threads)
        self.qpos, self.qvel = self.batch.bind("qpos"), self.batch.bind("qvel")
        self.ctrl = self.batch.bind("ctrl")

    def load(self) -> None:
        """Take each env's state (just reset) into the batch."""
        for row, env in zip(self.batch.state, self.envs, strict=True):
            mujoco.mj_getState(env.model, env.data, row, STATE)

    def step(self, actions: np.ndarray) -> None:
        """One env step of every env. MuJoCo clamps ctrl to ctrlrange [-1, 1]."""
        self.ctrl[:] = actions
        self.batch.step(nstep=self.frame_skip)

    def collect(self, b: StepBatch) -> None:
        """Write every env's state into `b` (SkillEnv.observe_into, xy_into and pitch, by rows)."""
        qpos, qvel, p = self.qpos, self.qvel, self.position_dims
        b.obs[:, : self.nq] = qpos
        b.obs[:, self.nq :] = qvel
        b.xy[:, :p] = qpos[:, :p]
        b.xy[:, p:] = 0.0
        b.pitch[:] = self.env_class.pitch_rows(qpos)
        b.qpos[:] = qpos
        b.qvel[:] = qvel
