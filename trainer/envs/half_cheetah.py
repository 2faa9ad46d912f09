"""`half_cheetah`: Gymnasium HalfCheetah-v5 with x kept in the observation (18-D: qpos 9 + qvel 9).

Position is 1-D (xy = (x, 0)); pitch is the root hinge `rooty` (qpos[2]).
"""

from __future__ import annotations

import math

import numpy as np

from collie.mjmodels.quiet import quiet_compile
from trainer.envs.gym_mujoco import GymnasiumMujocoEnv


class HalfCheetahEnv(GymnasiumMujocoEnv):
    name = "half_cheetah"
    position_dims = 1
    asset = "half_cheetah.xml"
    batched_physics = True
    # From `python -m trainer.envs.normalizer --env half_cheetah` (see normalizer.py).
    obs_mean = np.array(
        [
            -0.4017,
            -0.09062,
            0.2057,
            0.008407,
            0.02111,
            -0.01147,
            0.03203,
            -0.04018,
            -0.03601,
            -0.07291,
            -0.02703,
            0.02707,
            0.02687,
            -0.06055,
            0.04214,
            0.01631,
            0.03352,
            0.009566,
        ],
        dtype=np.float32,
    )
    obs_std = np.array(
        [
            1.217,
            0.09512,
            0.5158,
            0.2531,
            0.2746,
            0.2646,
            0.3262,
            0.3032,
            0.2822,
            0.7494,
            0.7664,
            1.597,
            5.556,
            6.757,
            6.961,
            6.233,
            6.585,
            6.001,
        ],
        dtype=np.float32,
    )

    def __init__(self, episode_steps: int = 200, seed: int | None = None) -> None:
        from gymnasium.envs.mujoco.half_cheetah_v5 import HalfCheetahEnv as GymCheetah

        with quiet_compile():
            gym_env = GymCheetah(exclude_current_positions_from_observation=False)
        super().__init__(gym_env, episode_steps, seed)

    def pitch(self) -> float:
        """rooty wrapped to [-π, π): the hinge is unbounded, and a cheetah that rolled a full
        turn is upright again, so |pitch| > π/2 means "on its back" (Not-Flip) at any time."""
        return (float(self.data.qpos[2]) + math.pi) % (2.0 * math.pi) - math.pi

    @classmethod
    def pitch_rows(cls, qpos: np.ndarray) -> np.ndarray:
        return (qpos[:, 2] + math.pi) % (2.0 * math.pi) - math.pi
