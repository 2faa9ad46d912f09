"""The shape every collie environment shares: a MuJoCo model stepped with a fixed episode length.

Episodes never terminate early (skill discovery ignores rewards and health), so every episode is
exactly `episode_steps` long and only `truncated` ends it. Observations are float32 vectors, or
uint8 images for pixel envs (`obs_shape`, `obs_dtype` say which); info carries
what the rest of collie needs per state: `xy` (task rules, metrics), `pitch` (Not-Flip) and
copies of `qpos`/`qvel` (exact 3-D replay in the labeling UI).
"""

from __future__ import annotations

import abc
import math
from pathlib import Path
from typing import Any, ClassVar

import mujoco
import numpy as np

from collie import mjmodels


class SkillEnv(abc.ABC):
    """A reward-free MuJoCo environment with the Gymnasium reset/step API."""

    name: str
    position_dims: int  # 2 for planar robots, 1 for HalfCheetah (y is reported as 0)
    obs_mean: np.ndarray  # broadcastable to obs_shape (0-d for pixels)
    obs_std: np.ndarray
    metric_bin_size: ClassVar[float] = 1.0  # side of the coverage metric's x-y bins
    has_layout: ClassVar[bool] = False  # True: the constructor takes a `layout_seed` (random scenery)
    # True: SkillEnv's own advance/observe_into/xy_into and a `pitch_rows` equal to `pitch`, so that
    # VectorEnv may step many copies in one mujoco.batch call (trainer/envs/batched.py)
    batched_physics: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for stats in ("obs_mean", "obs_std"):  # shared class constants: guard against in-place edits
            if isinstance(cls.__dict__.get(stats), np.ndarray):
                cls.__dict__[stats].setflags(write=False)

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData, frame_skip: int, episode_steps: int, seed: int | None
    ) -> None:
        if episode_steps < 1:
            raise ValueError(f"episode_steps must be >= 1, got {episode_steps}")
        self.model = model
        self.data = data
        self.frame_skip = frame_skip
        self.episode_steps = episode_steps
        self.nq: int = model.nq
        self.nv: int = model.nv
        self.action_dim: int = model.nu
        first = self.observe()
        self.obs_shape: tuple[int, ...] = first.shape
        self.obs_dtype: np.dtype = first.dtype
        self.obs_dim: int = first.size
        self.t = -1  # -1 until the first reset
        self._first_seed = seed  # used by the first reset() that passes no seed (Gymnasium convention)

    # -- what subclasses provide -------------------------------------------------------------

    # The models live in collie.mjmodels (shared with the labeling UI's replay), by env name.
    @classmethod
    def mjcf_path(cls) -> Path:
        """The MJCF file this environment's model is compiled from (for replay elsewhere)."""
        return mjmodels.mjcf_path(cls.name)

    @classmethod
    def model_xml(cls, layout_seed: int | None = None) -> str:
        """The MJCF text of the model, self-contained (what a replay viewer compiles)."""
        return mjmodels.model_xml(cls.name, layout_seed)

    @classmethod
    def load_model(cls, layout_seed: int | None = None) -> mujoco.MjModel:
        """The compiled model, exactly as the env simulates (and renders) it."""
        return mjmodels.load_model(cls.name, layout_seed)

    @abc.abstractmethod
    def _reset_state(self, seed: int | None) -> None:
        """Put `data` in a fresh initial state; `seed` reseeds the env's RNG when not None."""

    def pitch(self) -> float:
        """Body pitch in radians; nan where the robot has no orientation."""
        return math.nan

    @classmethod
    def pitch_rows(cls, qpos: np.ndarray) -> np.ndarray:
        """`pitch` of many states at once, from their (n, nq) qpos (envs with `batched_physics`)."""
        return np.full(len(qpos), math.nan)

    # -- the shared mechanics (also used directly by VectorEnv's tight loop) -----------------

    def advance(self, action: np.ndarray) -> None:
        """Apply one action for one env step. MuJoCo clamps ctrl to ctrlrange [-1, 1]."""
        if self.t < 0:
            raise RuntimeError(f"{self.name}: call reset() before step()")
        if self.t >= self.episode_steps:
            raise RuntimeError(f"{self.name}: episode over after {self.episode_steps} steps; call reset()")
        self.data.ctrl[:] = action
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        self.t += 1

    def observe_into(self, out: np.ndarray) -> None:
        """Write the observation [qpos, qvel] into a preallocated float32 row."""
        out[: self.nq] = self.data.qpos
        out[self.nq :] = self.data.qvel

    def observe(self) -> np.ndarray:
        return np.concatenate((self.data.qpos, self.data.qvel)).astype(np.float32)

    def xy_into(self, out: np.ndarray) -> None:
        """Write the (x, y) position; the root's first slide joints hold it, y = 0 for 1-D robots."""
        out[: self.position_dims] = self.data.qpos[: self.position_dims]
        out[self.position_dims :] = 0.0

    def xy(self) -> np.ndarray:
        out = np.zeros(2)
        self.xy_into(out)
        return out

    def info(self) -> dict[str, Any]:
        return {"xy": self.xy(), "pitch": self.pitch(), "qpos": self.data.qpos.copy(), "qvel": self.data.qvel.copy()}

    # -- Gymnasium API -----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        if seed is None and self._first_seed is not None:
            seed = self._first_seed
        self._first_seed = None
        self._reset_state(seed)
        self.t = 0
        return self.observe(), self.info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.advance(action)
        return self.observe(), 0.0, False, self.t >= self.episode_steps, self.info()

    def close(self) -> None:  # noqa: B027 (optional hook: most envs hold nothing to release)
        """Release resources; nothing by default, as no renderer is ever opened here."""
