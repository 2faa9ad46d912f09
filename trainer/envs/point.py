"""`point`: a nearly kinematic point mass on an unbounded plane, collie's fast env for CI and CPU runs.

Dynamics live in point.xml: full action moves the point 0.25 units per step, so a 200-step
episode can travel about 50 units. Reset puts it within ±0.1 of the origin, at rest.
"""

from __future__ import annotations

import mujoco
import numpy as np

from trainer.envs.base import SkillEnv


class PointEnv(SkillEnv):
    """Observation [x, y, vx, vy] (float32); action: 2-D force command in [-1, 1]."""

    name = "point"
    position_dims = 2
    # Chosen, not measured (random-action rollouts barely leave the origin, which would make the
    # positions of any real skill huge): positions / 10 puts a full episode's straight-line travel
    # (~50 units) at ~5 and the task regions (radii 4–20) at O(1); velocities / 5 maps full speed
    # (5 units/s) to 1.
    obs_mean = np.zeros(4, dtype=np.float32)
    obs_std = np.array([10.0, 10.0, 5.0, 5.0], dtype=np.float32)
    reset_noise = 0.1
    batched_physics = True

    def __init__(self, episode_steps: int = 200, seed: int | None = None) -> None:
        model = self.load_model()
        super().__init__(model, mujoco.MjData(model), frame_skip=1, episode_steps=episode_steps, seed=seed)
        self._rng = np.random.default_rng(seed)

    def _reset_state(self, seed: int | None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = self._rng.uniform(-self.reset_noise, self.reset_noise, size=self.nq)
        mujoco.mj_forward(self.model, self.data)
