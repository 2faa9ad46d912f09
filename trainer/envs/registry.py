"""The environment registry: one line per env name, classes imported only when that env is used.

Lazy imports keep `point` free of Gymnasium.
To add an env: write a `SkillEnv` subclass in its own module and add one `_register` line.
"""

from __future__ import annotations

import importlib

from collie import mjmodels
from trainer.envs.base import SkillEnv

_REGISTRY: dict[str, str] = {}  # name -> "module:Class"


def _register(name: str, target: str) -> None:
    _REGISTRY[name] = target


_register("point", "trainer.envs.point:PointEnv")
_register("ant", "trainer.envs.ant:AntEnv")
_register("half_cheetah", "trainer.envs.half_cheetah:HalfCheetahEnv")
_register("quadruped", "trainer.envs.quadruped:QuadrupedEnv")
_register("humanoid", "trainer.envs.humanoid:HumanoidEnv")
_register("car", "trainer.envs.car:CarEnv")

ENV_NAMES: tuple[str, ...] = tuple(_REGISTRY)


def env_class(name: str) -> type[SkillEnv]:
    """The class registered under `name`; ValueError listing the valid names otherwise."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown env {name!r}; valid names: {', '.join(ENV_NAMES)}")
    module, cls = _REGISTRY[name].split(":")
    return getattr(importlib.import_module(module), cls)


def _layout(cls: type[SkillEnv], layout_seed: int | None) -> dict[str, int]:
    """The layout argument for envs with random scenery (the car's hazards); ignored by the others,
    so callers can always pass their experiment seed."""
    return {"layout_seed": layout_seed} if cls.has_layout and layout_seed is not None else {}


def make_env(name: str, seed: int | None = None, episode_steps: int = 200, layout_seed: int | None = None) -> SkillEnv:
    """Build one env; `seed` seeds its first reset() (later resets may pass their own);
    `layout_seed` fixes random scenery for a whole experiment (envs with `has_layout`)."""
    cls = env_class(name)
    return cls(episode_steps=episode_steps, seed=seed, **_layout(cls, layout_seed))


# The models themselves (what a replay viewer rebuilds) come from the light collie.mjmodels.
model_path, model_xml, load_model = mjmodels.mjcf_path, mjmodels.model_xml, mjmodels.load_model
