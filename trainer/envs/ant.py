"""`ant`: Gymnasium Ant-v5 with x, y kept in the observation (29-D: qpos 15 + qvel 14).

No contact forces in the observation (as METRA's Ant), no early termination, reward ignored.
"""

from __future__ import annotations

import math

import numpy as np

from trainer.envs.gym_mujoco import GymnasiumMujocoEnv


def quat_pitch(w: float, x: float, y: float, z: float) -> float:
    """Pitch of a body from its orientation quaternion, in (-π, π].

    atan2 of the body x-axis' downward tilt against the body z-axis' height: equal to the Euler
    pitch for a pure pitch rotation, and |pitch| > π/2 exactly when the body is upside down
    (its z-axis points below the horizon), so a Not-Flip style rule works for any robot.
    """
    norm2 = w * w + x * x + y * y + z * z  # MuJoCo leaves qpos quaternions unnormalised
    return math.atan2(2.0 * (w * y - x * z) / norm2, 1.0 - 2.0 * (x * x + y * y) / norm2)


class AntEnv(GymnasiumMujocoEnv):
    name = "ant"
    position_dims = 2
    asset = "ant.xml"
    batched_physics = True
    # From `python -m trainer.envs.normalizer --env ant` (random-action rollouts; see normalizer.py).
    obs_mean = np.array(
        [
            -0.1404,
            -0.08206,
            0.5896,
            0.4112,
            0.03865,
            0.01894,
            -0.002434,
            -0.006597,
            0.8661,
            -0.001544,
            -0.8692,
            0.004333,
            -0.8692,
            -0.006979,
            0.8689,
            -0.0193,
            -0.009483,
            -0.03135,
            0.04939,
            0.01927,
            -0.02575,
            -0.004064,
            0.07394,
            0.0006468,
            -0.06937,
            -0.0004222,
            -0.06846,
            -0.00172,
            0.06574,
        ],
        dtype=np.float32,
    )
    obs_std = np.array(
        [
            1.598,
            1.668,
            0.2588,
            0.4988,
            0.4576,
            0.4294,
            0.4319,
            0.4092,
            0.2905,
            0.4074,
            0.2911,
            0.411,
            0.2916,
            0.4115,
            0.291,
            0.7673,
            0.7966,
            0.8904,
            1.717,
            1.707,
            1.85,
            4.551,
            4.161,
            4.54,
            4.16,
            4.556,
            4.128,
            4.577,
            4.13,
        ],
        dtype=np.float32,
    )

    def __init__(self, episode_steps: int = 200, seed: int | None = None) -> None:
        from gymnasium.envs.mujoco.ant_v5 import AntEnv as GymAnt  # heavy import, only when used

        gym_env = GymAnt(
            exclude_current_positions_from_observation=False,
            include_cfrc_ext_in_observation=False,
            terminate_when_unhealthy=False,
        )
        super().__init__(gym_env, episode_steps, seed)

    def pitch(self) -> float:
        w, x, y, z = self.data.qpos[3:7]
        return quat_pitch(float(w), float(x), float(y), float(z))

    @classmethod
    def pitch_rows(cls, qpos: np.ndarray) -> np.ndarray:
        w, x, y, z = qpos[:, 3:7].T
        norm2 = w * w + x * x + y * y + z * z  # as quat_pitch
        return np.arctan2(2.0 * (w * y - x * z) / norm2, 1.0 - 2.0 * (x * x + y * y) / norm2)
