"""Small offscreen camera images on the CPU: MuJoCo's OpenGL renderer on a headless context.

Speed comes from what is switched off: shadows, reflections, skybox and multisampling cost far
more than the 64×64 pixels themselves (≈ 18 frames/s with dm_control's defaults, ≈ 650/s here
on Mesa's EGL; `benchmarks/bench_pixels.py` measures it). The GL backend is picked here rather
than through `mujoco.Renderer`, whose choice is frozen by MUJOCO_GL at `import mujoco`, often before
anyone could set it: EGL unless MUJOCO_GL=osmesa.

One camera is shared by every env of a kind in the process (`shared_camera`): a GL context holds
≈ 60 MB, and a trainer has 8 training envs plus 48 evaluation envs that never render at once.
Sharing is sound because all envs of a kind compile the same model; each render takes the data
of the env being drawn.
"""

from __future__ import annotations

import atexit
import os
from typing import Any

import mujoco
import numpy as np

_OFF = (
    mujoco.mjtRndFlag.mjRND_SHADOW,
    mujoco.mjtRndFlag.mjRND_REFLECTION,
    mujoco.mjtRndFlag.mjRND_SKYBOX,
    mujoco.mjtRndFlag.mjRND_FOG,
    mujoco.mjtRndFlag.mjRND_HAZE,
)


def _gl_context(size: int) -> Any:
    if os.environ.get("MUJOCO_GL", "egl").lower() == "osmesa":
        from mujoco.osmesa import GLContext
    else:
        from mujoco.egl import GLContext  # also sets PYOPENGL_PLATFORM=egl when unset
    return GLContext(size, size)


class OffscreenCamera:
    """Renders one fixed camera of `model` to (3, size, size) uint8 images, channels first."""

    def __init__(self, model: mujoco.MjModel, camera: str, size: int = 64) -> None:
        self.model, self.size = model, size
        # Read by the context created below: no multisampling, and coarse tessellation of spheres and
        # capsules (invisible at 64×64; the humanoid's capsules otherwise halve the frame rate).
        model.vis.quality.offsamples = 0
        model.vis.quality.numslices, model.vis.quality.numstacks = 8, 4
        self._gl = _gl_context(size)
        self._gl.make_current()
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_50)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        self._scene = mujoco.MjvScene(model, maxgeom=model.ngeom + 100)
        for flag in _OFF:
            self._scene.flags[flag] = 0
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = model.camera(camera).id
        self._rect = mujoco.MjrRect(0, 0, size, size)
        self._rgb = np.empty((size, size, 3), np.uint8)

    def render(self, data: mujoco.MjData, out: np.ndarray | None = None) -> np.ndarray:
        """The camera image of `data` (a state of this model), written into `out` if given."""
        self._gl.make_current()
        mujoco.mjv_updateScene(
            self.model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        mujoco.mjr_render(self._rect, self._scene, self._context)
        mujoco.mjr_readPixels(self._rgb, None, self._rect, self._context)
        if out is None:
            out = np.empty((3, self.size, self.size), np.uint8)
        out[:] = self._rgb[::-1].transpose(2, 0, 1)  # OpenGL rows run bottom-up
        return out

    def close(self) -> None:
        if self._gl is not None:
            self._gl.make_current()
            self._context.free()
            self._gl.free()
            self._gl = None


_SHARED: dict[str, OffscreenCamera] = {}


def shared_camera(key: str, model: mujoco.MjModel, camera: str, size: int = 64) -> OffscreenCamera:
    """The process-wide camera for `key` (an env name), created from the first model asking."""
    if key not in _SHARED:
        _SHARED[key] = OffscreenCamera(model, camera, size)
        if len(_SHARED) == 1:  # registered after the first GL context, so it runs before EGL's own teardown
            atexit.register(close_shared_cameras)
    return _SHARED[key]


def close_shared_cameras() -> None:
    while _SHARED:
        _SHARED.popitem()[1].close()
