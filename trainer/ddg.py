"""DDG* — the online variant of DDG (Klemsdal et al., 2021) used as a baseline (Section 5.1, App. E).

DDG trains a classifier to tell expert states from the rest and lets skill discovery see states
only through that classifier's encoder — a projection onto the subspace the expert cares about.
As the paper does, DDG* runs on METRA (not DIAYN) for a cleaner comparison, and trains the
classifier online on the labelled segments (trainer/instruction.py):
    φ(s) = head(encoder(s)),  encoder frozen for φ's update, refitted whenever labels change
and then METRA unchanged (w ≡ 1): Eqs. 9–11 on this φ. Before the first labels the encoder has
its random initial weights, a random projection of width `projection_dim`.
"""

from __future__ import annotations

import torch
from torch import nn

from trainer.config import Config
from trainer.instruction import InstructionClassifier
from trainer.metra import Metra
from trainer.networks import SkillLatent
from trainer.optim import adam


class ProjectedLatent(nn.Module):
    """φ(s) = head(encoder(s)) with no gradient into the encoder (the classifier owns it)."""

    def __init__(self, encoder: nn.Module, projection_dim: int, skill_dim: int, hidden: int, layers: int) -> None:
        super().__init__()
        self.encoder = encoder
        self.head = SkillLatent(projection_dim, skill_dim, hidden, layers)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            features = self.encoder(obs)
        return self.head(features)


def attach_projection(agent: Metra, classifier: InstructionClassifier, cfg: Config) -> None:
    """Replace the agent's φ by head ∘ encoder; φ's optimiser then trains the head only."""
    phi = ProjectedLatent(classifier.net.encoder, cfg.projection_dim, agent.prior.dim, cfg.hidden, cfg.layers)
    agent.phi = phi.to(agent.device)  # type: ignore[assignment]  # a SkillLatent in all but its class
    agent.phi_opt = adam(phi.head.parameters(), cfg.lr, cfg.fused_adam)
