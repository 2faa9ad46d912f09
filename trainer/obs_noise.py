"""Noisy observations for the robustness ablation (Appendix F, "Evaluation under noisy observation"):
the agent observes ŝ = (1 + x)·s with x ~ N(0, σ²I) drawn afresh for every state (paper: σ² = 0.01,
i.e. `--obs-noise 0.1`). Positions and pitch used by task rules, labels and metrics stay exact.

The noise of an episode is drawn from its reset seed, so rollouts stay reproducible and a resumed
run sees the same noise as an uninterrupted one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from trainer.envs import StepBatch, VectorEnv


class NoisyObservations:
    """Wraps a VectorEnv (same interface): obs ← obs·(1 + σ·N(0, I)) after every reset and step."""

    def __init__(self, env: VectorEnv, std: float) -> None:
        if std < 0:
            raise ValueError(f"obs noise std must be ≥ 0, got {std}")
        self.env, self.std = env, float(std)
        self.rng = np.random.default_rng(0)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.env, name)

    def _noisy(self, b: StepBatch) -> StepBatch:
        b.obs = (b.obs * (1.0 + self.std * self.rng.standard_normal(b.obs.shape))).astype(b.obs.dtype)
        return b

    def reset(self, seeds: Sequence[int]) -> StepBatch:
        self.rng = np.random.default_rng([int(s) for s in seeds])
        return self._noisy(self.env.reset(seeds))

    def step(self, actions: np.ndarray, out: StepBatch | None = None) -> StepBatch:
        return self._noisy(self.env.step(actions, out))
