"""The environment registry: one line per env name, classes imported only when that env is used.

Lazy imports keep `point` (and `model_path`, which the labeling UI calls) free of Gymnasium.
To add an env: write a `SkillEnv` subclass in its own module and add one `_register` line.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import mujoco

from trainer.envs.base import SkillEnv
from trainer.envs.quiet import quiet_compile

_REGISTRY: dict[str, str] = {}  # name -> "module:Class"


def _register(name: str, target: str) -> None:
    _REGISTRY[name] = target


_register("point", "trainer.envs.point:PointEnv")
_register("ant", "trainer.envs.ant:AntEnv")
_register("half_cheetah", "trainer.envs.half_cheetah:HalfCheetahEnv")

ENV_NAMES: tuple[str, ...] = tuple(_REGISTRY)


def env_class(name: str) -> type[SkillEnv]:
    """The class registered under `name`; ValueError listing the valid names otherwise."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown env {name!r}; valid names: {', '.join(ENV_NAMES)}")
    module, cls = _REGISTRY[name].split(":")
    return getattr(importlib.import_module(module), cls)


def make_env(name: str, seed: int | None = None, episode_steps: int = 200) -> SkillEnv:
    """Build one env; `seed` seeds its first reset() (later resets may pass their own)."""
    return env_class(name)(episode_steps=episode_steps, seed=seed)


def model_path(name: str) -> Path:
    """The MJCF file the env `name` is built from, so a viewer can rebuild the exact model."""
    return env_class(name).mjcf_path()


def model_xml(name: str) -> str:
    return model_path(name).read_text()


def load_model(name: str) -> mujoco.MjModel:
    """The compiled MuJoCo model of env `name` (what a replay viewer needs), compiled quietly."""
    with quiet_compile():
        return mujoco.MjModel.from_xml_path(str(model_path(name)))
