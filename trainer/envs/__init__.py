"""collie's environments: `point`, `ant`, `half_cheetah`, one factory, Gymnasium reset/step API.

    env = make_env("ant", seed=0)            # one env: reset() -> (obs, info), step(a) -> 5-tuple
    vec = VectorEnv("point", num_envs=8)     # the trainer's lockstep batch of envs
    model_path("ant")                         # the MJCF file, to rebuild the model for replay
    load_model("half_cheetah")                # ... or the compiled mujoco.MjModel itself
"""

from trainer.envs.base import SkillEnv
from trainer.envs.rate import raw_step_rate
from trainer.envs.registry import ENV_NAMES, env_class, load_model, make_env, model_path, model_xml
from trainer.envs.vector import StepBatch, VectorEnv

__all__ = [
    "ENV_NAMES",
    "SkillEnv",
    "StepBatch",
    "VectorEnv",
    "env_class",
    "load_model",
    "make_env",
    "model_path",
    "model_xml",
    "raw_step_rate",
]
