"""The names of collie's environments, one list for every process: the trainer simulates them
(trainer/envs), the labeling UI replays their models (collie/mjmodels), and the service takes runs
of them only (RunCreate.env)."""

from __future__ import annotations

from typing import Literal, get_args

EnvName = Literal["point", "ant", "half_cheetah", "quadruped", "humanoid", "car"]
ENV_NAMES: tuple[str, ...] = get_args(EnvName)
PIXEL_ENVS = frozenset({"quadruped", "humanoid"})  # they observe 64×64 pixel frames; the others state vectors
# (nq, nv) of each env's MuJoCo model, so that the service can refuse a run whose segments the
# labeling UI could not replay without importing MuJoCo (tests/test_envs.py checks them against the models)
ENV_JOINTS: dict[str, tuple[int, int]] = {
    "point": (2, 2),
    "ant": (15, 14),
    "half_cheetah": (9, 9),
    "quadruped": (23, 22),
    "humanoid": (28, 27),
    "car": (9, 8),
}
