"""`humanoid`: dm_control's Humanoid (21 actuators), seen through pixels (dmc.py).

Initial state as dm_control's Humanoid tasks: random joint angles and root orientation, redrawn
until nothing touches. A control step is 5 physics steps of 5 ms; with action repeat 2 an agent
step is 50 ms (10 s per 200-step episode).
"""

from __future__ import annotations

from typing import Any

from trainer.envs.dmc import DmcPixelEnv


class HumanoidEnv(DmcPixelEnv):
    name = "humanoid"
    substeps = 5  # dm_control: control timestep 0.025 s / physics timestep 0.005 s

    def dmc_task(self, seed: int | None) -> Any:
        from dm_control.suite import humanoid

        return humanoid.Humanoid(move_speed=0.0, pure_state=False, random=seed)
