"""dm_control robots seen through pixels: 64×64 RGB from a tracking camera, 3 stacked frames,
action repeat 2, over a floor whose colour encodes position (floor.py).

dm_control supplies the robot's MJCF and its episode initialisation (the suite task's
`initialize_episode`, seeded); stepping and rendering bypass its `Environment` (rewards and
observation dicts are not needed). The model is dm_control's XML edited through `mujoco.MjSpec`:
a coloured floor material and a "pixels" camera that follows the centre of mass from behind and
above. x-y (task rules, metrics), pitch and qpos/qvel come from physics, not pixels.
"""

from __future__ import annotations

import abc
import os
from typing import Any, ClassVar

import numpy as np

from collie.mjmodels import PIXEL_CAMERA
from collie.mjmodels.floor import paint_floor
from collie.mjmodels.quiet import quiet_compile
from trainer.envs.ant import quat_pitch
from trainer.envs.base import SkillEnv
from trainer.envs.offscreen import shared_camera

# dm_control picks its GL backend at import; without this it tries GLFW, which needs a display.
os.environ.setdefault("MUJOCO_GL", "egl")


class DmcPixelEnv(SkillEnv):
    """A dm_control robot with a free root joint, observed as (3·frames, size, size) uint8 images."""

    position_dims = 2
    obs_mean = np.array(0.0, dtype=np.float32)  # pixels are only scaled to [0, 1] (no statistics)
    obs_std = np.array(255.0, dtype=np.float32)
    image_size: ClassVar[int] = 64
    frame_stack: ClassVar[int] = 3
    action_repeat: ClassVar[int] = 2
    substeps: ClassVar[int]  # physics steps per dm_control control step

    # -- what each robot provides -------------------------------------------------------------

    @abc.abstractmethod
    def dmc_task(self, seed: int | None) -> Any:
        """The dm_control suite task whose `initialize_episode` draws the initial state."""

    # -- the env --------------------------------------------------------------------------------

    def __init__(self, episode_steps: int = 200, seed: int | None = None) -> None:
        from dm_control.mujoco import Physics

        with quiet_compile():
            self.physics = Physics.from_xml_string(self.model_xml())
        model = self.physics.model.ptr
        paint_floor(model)
        self._camera = shared_camera(self.name, model, PIXEL_CAMERA, self.image_size)
        self._frames = np.zeros((3 * self.frame_stack, self.image_size, self.image_size), np.uint8)
        self._task = self.dmc_task(seed)
        super().__init__(
            model,
            self.physics.data.ptr,
            frame_skip=self.action_repeat * self.substeps,
            episode_steps=episode_steps,
            seed=seed,
        )

    def _reset_state(self, seed: int | None) -> None:
        if seed is not None:
            self._task = self.dmc_task(seed)
        with self.physics.reset_context():
            self._task.initialize_episode(self.physics)
        frame = self._camera.render(self.data)
        self._frames[:] = np.tile(frame, (self.frame_stack, 1, 1))  # the first frame fills the stack

    def advance(self, action: np.ndarray) -> None:
        super().advance(action)
        self._frames[:-3] = self._frames[3:]  # oldest frame out, newest in last
        self._camera.render(self.data, out=self._frames[-3:])

    def render(self) -> np.ndarray:
        """The camera image of the current state, (3, size, size) uint8 (the newest frame of a step)."""
        return self._camera.render(self.data)

    def observe_into(self, out: np.ndarray) -> None:
        out[:] = self._frames

    def observe(self) -> np.ndarray:
        return self._frames.copy()

    def pitch(self) -> float:
        w, x, y, z = self.data.qpos[3:7]
        return quat_pitch(float(w), float(x), float(y), float(z))
