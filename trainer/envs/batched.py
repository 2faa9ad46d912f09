"""A group of copies of one plain env stepped as one `mujoco.batch.Batch` call.

For envs whose observation is [qpos, qvel] and whose step is "ctrl ← action; mj_step × frame_skip"
(`SkillEnv.batched_physics`), a step of the group is one C call that releases the GIL, and the
batch's state is read as (n, ·) arrays: no Python loop per env. The envs themselves still draw
each reset (Gymnasium's reset noise, the same as stepping them one by one); their whole
integration state, warm start included, then moves into the batch, whose steps are bit-identical
to `mj_step` on each env's MjData (MuJoCo's guarantee; tests/core/test_overlap.py checks it).
`nthread` > 1 spreads the group's envs over MuJoCo's own threads within the call (VectorEnv's
default, 2: bit-identical at any count, and no policy-side change: the rows still act as one group).
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
    def __init__(self, envs: Sequence[SkillEnv], rows: slice, nthread: int = 1) -> None:
        """`envs`: the group; `rows`: its rows in the VectorEnv's StepBatch; `nthread`: threads of
        each batch call, the caller's included."""
        first = envs[0]
        for env in envs:
            check_plain(env)
        self.env_class = type(first)
        self.envs = list(envs)
        self.frame_skip = first.frame_skip
        self.nq, self.position_dims = first.nq, first.position_dims
        self.rows = rows
        self.batch = Batch(first.model, len(envs), nthread=min(nthread, len(envs)))
        self.qpos, self.qvel = self.batch.bind("qpos"), self.batch.bind("qvel")
        self.ctrl = self.batch.bind("ctrl")
        self.episode_steps = first.episode_steps
        self.t = -1  # as SkillEnv.t

    def load(self) -> None:
        """Take each env's state (just reset) into the batch."""
        for row, env in zip(self.batch.state, self.envs, strict=True):
            mujoco.mj_getState(env.model, env.data, row, STATE)
        self.t = 0

    def step(self, actions: np.ndarray) -> None:
        """One env step of every env of the group (as SkillEnv.advance). MuJoCo clamps ctrl to
        ctrlrange [-1, 1]."""
        name = self.env_class.name
        if self.t < 0:
            raise RuntimeError(f"{name}: call reset() before step()")
        if self.t >= self.episode_steps:
            raise RuntimeError(f"{name}: episode over after {self.episode_steps} steps; call reset()")
        self.ctrl[:] = actions
        self.batch.step(nstep=self.frame_skip)
        self.t += 1

    def collect(self, b: StepBatch) -> None:
        """Write the group's state into its rows of `b` (SkillEnv.observe_into, xy_into, pitch)."""
        qpos, qvel, p, r = self.qpos, self.qvel, self.position_dims, self.rows
        b.obs[r, : self.nq] = qpos
        b.obs[r, self.nq :] = qvel
        b.xy[r, :p] = qpos[:, :p]
        b.xy[r, p:] = 0.0
        b.pitch[r] = self.env_class.pitch_rows(qpos)
        b.qpos[r] = qpos
        b.qvel[r] = qvel
