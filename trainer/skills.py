"""The skill prior p(z): continuous unit-norm vectors (Ant, point), one-hot (HalfCheetah), or — for
DIAYN as the reference runs it — a standard normal N(0, I) left unprojected."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from trainer.config import Config


class SkillPrior:
    def __init__(self, dim: int, discrete: bool, gaussian: bool = False) -> None:
        if discrete and dim < 2:
            raise ValueError("discrete skills need skill_dim ≥ 2")
        if discrete and gaussian:
            raise ValueError("a skill prior is one-hot or Gaussian, not both")
        self.dim, self.discrete, self.gaussian = dim, discrete, gaussian

    @classmethod
    def for_config(cls, cfg: Config) -> SkillPrior:
        """The run's prior: DIAYN's reference variant draws continuous z from N(0, I) (the reference's
        `--unit_length 0`); every other method and variant uses the unit sphere or one-hot skills."""
        gaussian = cfg.method == "diayn" and cfg.diayn == "reference" and not cfg.discrete_skills
        return cls(cfg.skill_dim, cfg.discrete_skills, gaussian)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """z ~ p(z): uniform one-hot, a standard normal, or a standard normal projected to the sphere."""
        if self.discrete:
            return np.eye(self.dim, dtype=np.float32)[rng.integers(0, self.dim, size=n)]
        z = rng.standard_normal((n, self.dim))
        if self.gaussian:
            return z.astype(np.float32)
        return (z / np.linalg.norm(z, axis=1, keepdims=True)).astype(np.float32)

    def evaluation_skills(self, n: int, seed: int = 0) -> np.ndarray:
        """Fixed skills for evaluation and plots: evenly spaced angles in 2-D, each one-hot in turn
        for discrete skills, seeded draws from the prior otherwise (Gaussian priors included, as the
        reference evaluates them)."""
        if self.discrete:
            return np.eye(self.dim, dtype=np.float32)[np.arange(n) % self.dim]
        if self.dim == 2 and not self.gaussian:
            angles = 2 * np.pi * np.arange(n) / n
            return np.stack([np.cos(angles), np.sin(angles)], axis=1).astype(np.float32)
        return self.sample(n, np.random.default_rng(seed))

    def reward_direction(self, z: np.ndarray) -> np.ndarray:
        """The vector that multiplies Δφ in the reward: z itself, or for one-hot skills the centred
        (z − mean z)·D/(D − 1), so that the other skills' directions are pushed away (METRA)."""
        if not self.discrete:
            return z
        return (z - z.mean(axis=-1, keepdims=True)) * self.dim / (self.dim - 1)
