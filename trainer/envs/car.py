"""`car`: Safety Gym's CarGoal1 hazard scene rebuilt on plain MuJoCo (safety-gymnasium does not
install on Python 3.11).

A two-wheeled car (car.xml) on an open floor with 8 hazards of radius 0.2 placed at random inside
±1.5, drawn once per experiment from `layout_seed` (collie.tasks.hazard_layout) and fixed for the
run. Hazards do not collide; the Hazard task judges entering one. Each episode starts at the
origin (±2 cm) with a random heading, as Safety Gym randomises the robot's rotation. A step is 10
physics steps of 2 ms (Safety Gym's frame skip), so 200 steps last 4 s and cover up to ≈ 2.5 m.

Observation (25-D float32): the car's own state [x, y, cos yaw, sin yaw, vx, vy, yaw rate,
left and right wheel speeds] (x-y included, as for Ant, so φ can see position) and a 16-bin
hazard pseudo-lidar (lidar.py). Coverage is measured in 0.01 × 0.01 bins (paper, Appendix E).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from collie.tasks import hazard_layout
from trainer.envs.ant import quat_pitch
from trainer.envs.base import SkillEnv
from trainer.envs.lidar import pseudo_lidar

LIDAR_BINS = 16
OWN_STATE = 9


class CarEnv(SkillEnv):
    name = "car"
    position_dims = 2
    metric_bin_size = 0.01
    has_layout = True
    # Chosen, not measured (random actions barely leave the start): positions over the hazard
    # square's half-width, speeds over the top speed (≈ 0.7 m/s, ≈ 4 rad/s turning, wheels
    # ≈ 17 rad/s); lidar readings are already in [0, 1].
    obs_mean = np.zeros(OWN_STATE + LIDAR_BINS, dtype=np.float32)
    obs_std = np.array([1.5, 1.5, 1, 1, 0.7, 0.7, 4, 17, 17] + [0.5] * LIDAR_BINS, dtype=np.float32)
    frame_skip = 10
    reset_noise = 0.02

    def __init__(self, episode_steps: int = 200, seed: int | None = None, layout_seed: int = 0) -> None:
        self.layout_seed = layout_seed
        self.hazards = hazard_layout(layout_seed)
        model = self.load_model(layout_seed)
        super().__init__(
            model, mujoco.MjData(model), frame_skip=self.frame_skip, episode_steps=episode_steps, seed=seed
        )
        self._rng = np.random.default_rng(seed)

    def _reset_state(self, seed: int | None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:2] = self._rng.uniform(-self.reset_noise, self.reset_noise, size=2)
        yaw = self._rng.uniform(-math.pi, math.pi)
        self.data.qpos[3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        mujoco.mj_forward(self.model, self.data)

    def yaw(self) -> float:
        w, x, y, z = self.data.qpos[3:7]
        return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))

    def observe_into(self, out: np.ndarray) -> None:
        qpos, qvel = self.data.qpos, self.data.qvel
        yaw = self.yaw()
        out[:OWN_STATE] = (qpos[0], qpos[1], math.cos(yaw), math.sin(yaw), qvel[0], qvel[1], qvel[5], qvel[6], qvel[7])
        pseudo_lidar(qpos[:2], yaw, self.hazards, LIDAR_BINS, out=out[OWN_STATE:])

    def observe(self) -> np.ndarray:
        out = np.empty(OWN_STATE + LIDAR_BINS, np.float32)
        self.observe_into(out)
        return out

    def pitch(self) -> float:
        w, x, y, z = self.data.qpos[3:7]
        return quat_pitch(float(w), float(x), float(y), float(z))
