"""Replay buffer B of whole trajectories. States are stored once per trajectory (T + 1 of them),
so s and s′ are not duplicated, and a segment σ = (s_t … s_{t+H−1}) is a slice. Raw observations
are stored in the env's dtype (pixel frame stacks as uint8, 4× smaller than float32);
normalisation happens when a batch is drawn. `dirty` marks the slots written since the replay log
(trainer/replay_log.py) last saved them, so a checkpoint writes only what changed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Batch:
    obs: np.ndarray  # (B, *obs_shape) s
    next_obs: np.ndarray  # (B, *obs_shape) s′
    action: np.ndarray  # (B, |A|)
    skill: np.ndarray  # (B, dim_z)
    xy: np.ndarray  # (B, 2) of s
    next_xy: np.ndarray  # (B, 2) of s′
    pitch: np.ndarray  # (B,) of s
    next_pitch: np.ndarray  # (B,) of s′


FIELDS = ("obs", "action", "skill", "xy", "pitch", "qpos", "qvel", "epoch")  # the per-trajectory arrays


def trajectories_held(capacity: int, steps: int) -> int:
    """How many whole trajectories of `steps` transitions a replay of `capacity` keeps (at least one)."""
    return max(1, capacity // steps)


class TrajectoryReplay:
    def __init__(
        self,
        capacity: int,
        steps: int,
        obs_shape: int | tuple[int, ...],
        action_dim: int,
        skill_dim: int,
        nq: int,
        nv: int,
        obs_dtype: np.dtype | type = np.float32,
    ) -> None:
        self.size = trajectories_held(capacity, steps)
        self.steps = steps
        n, t = self.size, steps + 1
        shape = (obs_shape,) if isinstance(obs_shape, int) else tuple(obs_shape)
        self.obs = np.zeros((n, t, *shape), obs_dtype)
        self.action = np.zeros((n, steps, action_dim), np.float32)
        self.skill = np.zeros((n, skill_dim), np.float32)
        self.xy = np.zeros((n, t, 2), np.float32)
        self.pitch = np.zeros((n, t), np.float32)
        self.qpos = np.zeros((n, t, nq), np.float32)
        self.qvel = np.zeros((n, t, nv), np.float32)
        self.epoch = np.zeros(n, np.int64)
        self.dirty = np.zeros(n, bool)  # written since the last save
        self.next, self.count = 0, 0

    @property
    def transitions(self) -> int:
        return self.count * self.steps

    def add(
        self,
        obs: np.ndarray,
        action: np.ndarray,
        skill: np.ndarray,
        xy: np.ndarray,
        pitch: np.ndarray,
        qpos: np.ndarray,
        qvel: np.ndarray,
        epoch: int,
    ) -> np.ndarray:
        """Store n trajectories (arrays with a leading n axis); returns their slot indices."""
        n = obs.shape[0]
        idx = (self.next + np.arange(n)) % self.size
        self.obs[idx], self.action[idx], self.skill[idx] = obs, action, skill
        self.xy[idx], self.pitch[idx] = xy, pitch
        self.qpos[idx], self.qvel[idx] = qpos, qvel
        self.epoch[idx] = epoch
        self.dirty[idx] = True
        self.next = int((self.next + n) % self.size)
        self.count = min(self.size, self.count + n)
        return idx

    def sample_indices(self, steps: int, batch_size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Trajectory slots and times (steps, batch_size) of `steps` batches: the same draws as
        `steps` calls of `sample`, made at once so that a device can gather them all."""
        i, t = np.empty((steps, batch_size), np.int64), np.empty((steps, batch_size), np.int64)
        for k in range(steps):
            i[k] = rng.integers(0, self.count, size=batch_size)
            t[k] = rng.integers(0, self.steps, size=batch_size)
        return i, t

    def sample(self, batch_size: int, rng: np.random.Generator) -> Batch:
        i, t = (x[0] for x in self.sample_indices(1, batch_size, rng))
        return self.gather(i, t)

    def gather(self, i: np.ndarray, t: np.ndarray) -> Batch:
        """The transitions (s_t, a_t, s_t+1) of trajectory slots i at times t."""
        return Batch(
            self.obs[i, t],
            self.obs[i, t + 1],
            self.action[i, t],
            self.skill[i],
            self.xy[i, t],
            self.xy[i, t + 1],
            self.pitch[i, t],
            self.pitch[i, t + 1],
        )

    def sample_windows(self, n: int, length: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """n random windows of `length` consecutive states: (trajectory slots, start indices)."""
        i = rng.integers(0, self.count, size=n)
        t = rng.integers(0, self.steps + 2 - length, size=n)
        return i, t

    def state_dict(self) -> dict[str, np.ndarray | int]:
        """Every stored trajectory at once (the replay log saves only what changed)."""
        keep = slice(0, self.count)
        return {key: getattr(self, key)[keep] for key in FIELDS} | {"next": self.next, "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        c = int(state["count"])
        for key in FIELDS:
            getattr(self, key)[:c] = state[key]
        self.next, self.count = int(state["next"]), c
        self.dirty[:c] = True
