"""collie's environments, one factory, Gymnasium reset/step API: `point`, `ant`, `half_cheetah`,
`car` (state vectors) and `quadruped`, `humanoid` (64×64 pixels; docs/envs.md).

    env = make_env("ant", seed=0)            # one env: reset() -> (obs, info), step(a) -> 5-tuple
    vec = VectorEnv("point", num_envs=8)     # the trainer's lockstep batch of envs
    make_env("car", layout_seed=3)            # the experiment seed places the car's hazards
    model_xml("quadruped")                    # self-contained MJCF text, to rebuild the model for replay
    load_model("car", layout_seed=3)          # ... or the compiled mujoco.MjModel itself
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
