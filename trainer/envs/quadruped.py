"""`quadruped`: dm_control's Quadruped on an empty floor, seen through pixels (dmc.py).

Initial state as dm_control's Quadruped tasks: a random orientation dropped just above the floor.
A control step is 4 physics steps of 5 ms; with action repeat 2 an agent step is 40 ms (8 s per
200-step episode).
"""

from __future__ import annotations

from typing import Any

from trainer.envs.dmc import DmcPixelEnv


class QuadrupedEnv(DmcPixelEnv):
    name = "quadruped"
    substeps = 4  # dm_control: control timestep 0.02 s / physics timestep 0.005 s

    def dmc_task(self, seed: int | None) -> Any:
        from dm_control.suite import quadruped

        return quadruped.Move(desired_speed=0.0, random=seed)
