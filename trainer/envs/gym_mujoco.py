"""Gymnasium's MuJoCo locomotion envs (v5) seen through collie's `SkillEnv`.

The Gymnasium env builds the model from its bundled MJCF file and draws the initial state
(its own reset noise and RNG), so both match Ant-v5 / HalfCheetah-v5 exactly. Stepping bypasses
its `step`: the reward, contact-cost and info bookkeeping cost ~20% of an Ant step and collie
ignores rewards. The state trajectory is the same (tests/test_envs.py checks it).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

from trainer.envs.base import SkillEnv


def gymnasium_asset(filename: str) -> Path:
    """Path of an MJCF file bundled with Gymnasium, found without importing Gymnasium."""
    spec = importlib.util.find_spec("gymnasium")
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError("gymnasium is not installed (pip install 'gymnasium[mujoco]')")
    return Path(next(iter(spec.submodule_search_locations))) / "envs" / "mujoco" / "assets" / filename


class GymnasiumMujocoEnv(SkillEnv):
    """Wraps a Gymnasium MujocoEnv instance; subclasses say which one and how to read pitch."""

    asset: str  # MJCF file name in Gymnasium's assets folder

    def __init__(self, gym_env: Any, episode_steps: int, seed: int | None) -> None:
        self._gym = gym_env
        super().__init__(gym_env.model, gym_env.data, gym_env.frame_skip, episode_steps, seed)

    @classmethod
    def mjcf_path(cls) -> Path:
        return gymnasium_asset(cls.asset)

    def _reset_state(self, seed: int | None) -> None:
        self._gym.reset(seed=seed)

    def close(self) -> None:
        self._gym.close()
