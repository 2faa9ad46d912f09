"""Gymnasium's MuJoCo locomotion envs (v5) seen through collie's `SkillEnv`.

The Gymnasium env builds the model from its bundled MJCF file and draws the initial state
(its own reset noise and RNG), so both match Ant-v5 / HalfCheetah-v5 exactly. Stepping bypasses
its `step`: the reward, contact-cost and info bookkeeping cost ~20% of an Ant step and collie
ignores rewards. The state trajectory is the same (tests/test_envs.py checks it).
"""

from __future__ import annotations

from typing import Any

from trainer.envs.base import SkillEnv


class GymnasiumMujocoEnv(SkillEnv):
    """Wraps a Gymnasium MujocoEnv instance; subclasses say which one and how to read pitch."""

    def __init__(self, gym_env: Any, episode_steps: int, seed: int | None) -> None:
        self._gym = gym_env
        super().__init__(gym_env.model, gym_env.data, gym_env.frame_skip, episode_steps, seed)

    def _reset_state(self, seed: int | None) -> None:
        self._gym.reset(seed=seed)

    def close(self) -> None:
        self._gym.close()
