"""The instruction classifier ψ shared by the online guided baselines DoDont* and DDG* (Appendix E).

DoDont and DDG train a classifier on pre-collected expert data; the online variants ("*") train it
on the segments labelled during skill discovery — the same D0/D1/D2 COLLIE builds, from the same
feedback source — and fine-tune it incrementally each time the labelled set changes.

    ψ(s) = σ(head(encoder(s))) ∈ (0, 1), the probability that a labeller finds s desirable.

Targets: bad 0, good 1, and neutral ½ (in the tasks with a single constraint the labels are only
bad and neutral; the midpoint keeps the "good" information of the composite tasks). Each label class
weighs equally in the binary cross-entropy, whatever its number of states. DoDont* uses 2ψ(s′) as
the weight of METRA's distance (trainer/dodont.py, on COLLIE's 0–2 scale); DDG* uses `encoder`
as the state projection φ reads (trainer/ddg.py).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from trainer.config import Config
from trainer.guidance import LabelledSets
from trainer.networks import mlp
from trainer.optim import adam, restore_kernel

TARGETS = (0.0, 0.5, 1.0)  # bad, neutral, good


class InstructionNet(nn.Module):
    def __init__(self, obs_dim: int, hidden: int, layers: int, projection_dim: int) -> None:
        super().__init__()
        self.encoder = mlp(obs_dim, hidden, layers, projection_dim)
        self.head = nn.Linear(projection_dim, 1)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Logit of ψ(s) for normalised states (B, d) → (B,)."""
        return self.head(self.encoder(obs)).squeeze(-1)


class InstructionClassifier:
    """ψ plus its optimiser, refitted when (and only when) the labelled segments change."""

    def __init__(self, obs_dim: int, cfg: Config, device: torch.device) -> None:
        self.net = InstructionNet(obs_dim, cfg.hidden, cfg.layers, cfg.projection_dim).to(device)
        self.opt = adam(self.net.parameters(), cfg.lr, cfg.fused_adam)
        self.fused_adam = cfg.fused_adam
        self.steps, self.device = cfg.classifier_steps, device
        self.fitted: tuple | None = None  # the labelled set ψ was last fitted to (query id, label)
        self.last_loss = float("nan")

    @property
    def trained(self) -> bool:
        return self.fitted is not None

    @staticmethod
    def key(labelled: LabelledSets) -> tuple:
        return tuple(sorted((q, s.label) for q, s in labelled.segments.items()))

    def refresh(self, labelled: LabelledSets) -> bool:
        """Fine-tune on every labelled state when the labelled set changed; True when it did."""
        key = self.key(labelled)
        if not key or key == self.fitted:
            return False
        self.fit(labelled.normalised())
        self.fitted = key
        return True

    def fit(self, sets: list[torch.Tensor]) -> float:
        """`steps` full-batch Adam steps of class-balanced binary cross-entropy on D0, D1, D2."""
        present = [(x, TARGETS[y]) for y, x in enumerate(sets) if x.shape[0] > 0]
        obs = torch.cat([x for x, _ in present]).to(self.device)
        target = torch.cat([torch.full((x.shape[0],), t, device=self.device) for x, t in present])
        weight = torch.cat(
            [torch.full((x.shape[0],), 1.0 / (len(present) * x.shape[0]), device=self.device) for x, _ in present]
        )
        for _ in range(self.steps):
            loss = (F.binary_cross_entropy_with_logits(self.net(obs), target, reduction="none") * weight).sum()
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            self.opt.step()
        self.last_loss = float(loss.detach())
        return self.last_loss

    @torch.no_grad()
    def prob(self, obs: torch.Tensor) -> torch.Tensor:
        """ψ(s) for normalised states."""
        return torch.sigmoid(self.net(obs))

    def state_dict(self) -> dict[str, Any]:
        return {
            "net": self.net.state_dict(),
            "opt": self.opt.state_dict(),
            "fitted": self.fitted,
            "last_loss": self.last_loss,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.opt.load_state_dict(state["opt"])
        restore_kernel(self.opt, self.fused_adam)
        self.fitted = None if state["fitted"] is None else tuple(tuple(x) for x in state["fitted"])
        self.last_loss = state["last_loss"]
