"""The names of collie's environments, one list for every process: the trainer simulates them
(trainer/envs), the labeling UI replays their models (collie/mjmodels), and the service takes runs
of them only (RunCreate.env)."""

from __future__ import annotations

from typing import Literal, get_args

EnvName = Literal["point", "ant", "half_cheetah", "quadruped", "humanoid", "car"]
ENV_NAMES: tuple[str, ...] = get_args(EnvName)
