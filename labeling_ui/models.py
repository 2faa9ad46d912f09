"""MuJoCo models for replay, and poses from a segment's qpos frames.

Models come from collie.mjmodels (numpy + mujoco, what the trainer's envs simulate); each env's model is compiled
once per process. A segment replays by kinematics only: qpos → body poses, no physics steps, so a
replay shows exactly the states the trainer recorded.
"""

from __future__ import annotations

import functools
import math
import threading
import time
from collections import defaultdict

import mujoco
import numpy as np

from collie.mjmodels import MODEL_NAMES, load_model


class ModelError(Exception):
    """The segment cannot be replayed: unknown env, a model that does not compile, or frames whose
    width does not fit the model."""


_locks: dict[str, threading.Lock] = defaultdict(threading.Lock)  # one per env: a slow compile blocks only its env
_locks_guard = threading.Lock()


@functools.lru_cache(maxsize=16)
def _compiled(env: str) -> mujoco.MjModel:
    return load_model(env)


def replay_model(env: str) -> mujoco.MjModel:
    """The compiled model of `env` (shared, read-only; each viewer keeps its own MjData)."""
    with _locks_guard:
        lock = _locks[env]
    try:
        with lock:
            return _compiled(env)
    except Exception as exc:  # unknown names raise ValueError, broken XML raises mujoco errors
        raise ModelError(f"cannot build the MuJoCo model for env '{env}': {exc}") from exc


def warm_models(envs: tuple[str, ...] = MODEL_NAMES, stop: threading.Event | None = None) -> dict[str, float]:
    """Compile every env's model ahead of the first labeler (quadruped takes about 1 s); returns
    env → seconds, NaN for a model that does not compile (its segments then say so). Stops
    between models once `stop` is set."""
    took = {}
    for env in envs:
        if stop is not None and stop.is_set():
            break
        start = time.perf_counter()
        try:
            replay_model(env)
            took[env] = time.perf_counter() - start
        except ModelError:
            took[env] = math.nan
    return took


class Poser:
    """Body poses of one model at fractional frame positions of a qpos sequence. Between two frames
    the configuration is interpolated on the joint manifold (quaternions stay unit), so slow-motion
    replay stays smooth at the display rate."""

    def __init__(self, model: mujoco.MjModel, qpos: np.ndarray) -> None:
        qpos = np.asarray(qpos, dtype=np.float64)
        if qpos.ndim != 2 or len(qpos) == 0:
            raise ModelError(f"a segment needs at least one qpos frame, got shape {qpos.shape}")
        if qpos.shape[1] != model.nq:
            raise ModelError(f"qpos frames have {qpos.shape[1]} values, the model has nq={model.nq}")
        if not np.isfinite(qpos).all():
            raise ModelError("qpos frames contain non-finite values")
        self.model = model
        self.data = mujoco.MjData(model)
        self.qpos = qpos
        self._step = np.zeros(model.nv)

    @property
    def n_frames(self) -> int:
        return len(self.qpos)

    def configuration(self, position: float) -> np.ndarray:
        """qpos at a fractional frame index (clamped to the segment)."""
        position = min(max(position, 0.0), self.n_frames - 1.0)
        i = int(np.floor(position))
        alpha = position - i
        if alpha < 1e-9 or i + 1 >= self.n_frames:
            return self.qpos[i].copy()
        # velocity that carries frame i to frame i+1 in unit time, then integrate a fraction of it
        mujoco.mj_differentiatePos(self.model, self._step, 1.0, self.qpos[i], self.qpos[i + 1])
        q = self.qpos[i].copy()
        mujoco.mj_integratePos(self.model, q, self._step, alpha)
        return q

    def pose(self, position: float) -> mujoco.MjData:
        """MjData with body poses (xpos, xmat) at `position`."""
        self.data.qpos[:] = self.configuration(position)
        mujoco.mj_kinematics(self.model, self.data)
        return self.data


def robot_size(model: mujoco.MjModel) -> float:
    """Rough radius of the robot at qpos0, from its non-world geoms (for camera distance)."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    moving = model.geom_bodyid > 0
    if not moving.any():
        return 1.0
    root = data.xpos[model.geom_bodyid[moving][0]]
    reach = np.linalg.norm(data.geom_xpos[moving] - root, axis=1) + model.geom_rbound[moving]
    return float(max(reach.max(), 0.1))
