"""The skill prior p(z): continuous unit-norm vectors (Ant, point) or one-hot (HalfCheetah)."""

from __future__ import annotations

import numpy as np


class SkillPrior:
    def __init__(self, dim: int, discrete: bool) -> None:
        if discrete and dim < 2:
            raise ValueError("discrete skills need skill_dim ≥ 2")
        self.dim, self.discrete = dim, discrete

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """z ~ p(z): uniform one-hot, or a standard normal projected to the unit sphere."""
        if self.discrete:
            return np.eye(self.dim, dtype=np.float32)[rng.integers(0, self.dim, size=n)]
        z = rng.standard_normal((n, self.dim))
        return (z / np.linalg.norm(z, axis=1, keepdims=True)).astype(np.float32)

    def evaluation_skills(self, n: int, seed: int = 0) -> np.ndarray:
        """Fixed skills for evaluation and plots: evenly spaced angles in 2-D, each one-hot in turn
        for discrete skills, seeded random unit vectors otherwise."""
        if self.discrete:
            return np.eye(self.dim, dtype=np.float32)[np.arange(n) % self.dim]
        if self.dim == 2:
            angles = 2 * np.pi * np.arange(n) / n
            return np.stack([np.cos(angles), np.sin(angles)], axis=1).astype(np.float32)
        return self.sample(n, np.random.default_rng(seed))

    def reward_direction(self, z: np.ndarray) -> np.ndarray:
        """The vector that multiplies Δφ in the reward: z itself, or for one-hot skills the centred
        (z − mean z)·D/(D − 1), so that the other skills' directions are pushed away (METRA)."""
        if not self.discrete:
            return z
        return (z - z.mean(axis=-1, keepdims=True)) * self.dim / (self.dim - 1)
