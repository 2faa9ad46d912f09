"""DIAYN (Eysenbach et al., 2019) on collie's SAC — the mutual-information baseline of Section 5.1.

Per gradient step, on a batch (s, a, z, s′):
  1. the skill discriminator q(z | s′) ascends  E[log q(z | s′)]
  2. SAC on the intrinsic reward  r(s, z, s′) = log q(z | s′) + log D
The discriminator is the network METRA calls φ (S → R^D), so checkpoints, the labelled-embedding
cache and evaluation need nothing new. Two variants (`--diayn`):

  reference (default), as the reference runs DIAYN (its METRA code with `--inner 0 --dual_reg 0
  --unit_length 0 --diayn_include_baseline 1 --alpha 0.1 --sac_lr_a -1`):
    continuous z ~ N(0, I) (not projected to the sphere); q(z | s) = N(z; μ(s), diag σ(s)²) with a
    learned σ from its own MLP (φ's shape, output bias log 1 = 0, floored at 1e-6, garage's
    independent-std Gaussian module); one-hot z: q = softmax(μ(s))_z; SAC's α fixed at 0.1.
    The reference adds −log(1/D) = log D to the reward for either prior (a constant for
    continuous z; the true −log p(z) of a one-hot prior).
  sphere (collie's first version): z on the unit sphere, q = N(z; φ(s), I), α learned as in METRA,
    r = log q(z | s′) (+ log D for one-hot z).
DIAYN asks for no labels: the guidance weight is ignored (w ≡ 1) and λ is never used.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from trainer.config import Config
from trainer.encoders import feature_dim, is_pixels
from trainer.metra import Metra, TorchBatch, WeightFn
from trainer.networks import SkillLatent, mlp
from trainer.optim import adam
from trainer.skills import SkillPrior

REFERENCE_ALPHA = 0.1  # the reference's DIAYN scripts: --alpha 0.1 with a zero α learning rate
DISCRIMINATOR_MIN_STD = 1e-6  # garage's Gaussian modules' default min_std


class GaussianDiscriminator(SkillLatent):
    """q(z | s) = N(μ(s), diag σ(s)²): forward() is μ (what φ-readers use), `log_std()` a second MLP."""

    def __init__(
        self, obs_dim: int, skill_dim: int, hidden: int, layers: int, xavier: bool, encoder: nn.Module | None = None
    ) -> None:
        super().__init__(obs_dim, skill_dim, hidden, layers, encoder)
        self.log_std_net = mlp(obs_dim, hidden, layers, skill_dim)
        if xavier:
            for module in (*self.net, *self.log_std_net):
                if isinstance(module, nn.Linear):  # the MLP heads; a pixel encoder keeps its own init
                    nn.init.xavier_uniform_(module.weight)
                    nn.init.zeros_(module.bias)
        else:
            last = self.log_std_net[-1]
            assert isinstance(last, nn.Linear)
            nn.init.zeros_(last.bias)  # σ = 1 at the start either way

    def log_std(self, obs: torch.Tensor) -> torch.Tensor:
        return self.log_std_net(self.encoder(obs)).clamp(min=math.log(DISCRIMINATOR_MIN_STD))


def skill_log_likelihood(
    logits_or_mean: torch.Tensor, z: torch.Tensor, discrete: bool, log_std: torch.Tensor | None = None
) -> torch.Tensor:
    """log q(z | s′): categorical for one-hot z, Gaussian (unit or given diagonal std) otherwise."""
    if discrete:
        return (F.log_softmax(logits_or_mean, dim=-1) * z).sum(-1)
    k = z.shape[-1]
    if log_std is None:
        return -0.5 * (z - logits_or_mean).pow(2).sum(-1) - 0.5 * k * math.log(2 * math.pi)
    var_term = ((z - logits_or_mean) * torch.exp(-log_std)).pow(2)
    return (-0.5 * var_term - log_std).sum(-1) - 0.5 * k * math.log(2 * math.pi)


def diayn_reward(log_q: torch.Tensor, dim: int, discrete: bool, variant: str = "reference") -> torch.Tensor:
    """r = log q(z | s′) + log D: the reference adds log D for any prior, `sphere` only for one-hot z."""
    return log_q + math.log(dim) if discrete or variant == "reference" else log_q


class Diayn(Metra):
    def __init__(
        self, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, cfg: Config, device: torch.device
    ) -> None:
        super().__init__(obs_shape, action_dim, prior, cfg, device)
        self.reference = cfg.diayn == "reference"
        if self.reference:  # φ's encoder (a CNN for pixels) feeds both heads
            encoder = self.phi.encoder if is_pixels(obs_shape) else None
            self.phi = GaussianDiscriminator(
                feature_dim(obs_shape), prior.dim, cfg.hidden, cfg.layers, cfg.init == "reference", encoder
            ).to(device)
            self.phi_opt = adam(self.phi.parameters(), cfg.lr, cfg.fused_adam)
            with torch.no_grad():
                self.log_alpha.fill_(np.log(REFERENCE_ALPHA))
            self.learn_alpha = False

    def update(self, b: TorchBatch, weight_fn: WeightFn | None) -> dict[str, torch.Tensor]:
        """One discriminator step, then SAC on r = log q(z | s′) + log D. `weight_fn` is ignored."""
        discrete = self.prior.discrete
        phi = self.phi
        log_std = phi.log_std(b.next_obs) if isinstance(phi, GaussianDiscriminator) and not discrete else None
        log_q = skill_log_likelihood(self.phi(b.next_obs), b.skill, discrete, log_std)
        disc_loss = -log_q.mean()
        self.phi_opt.zero_grad(set_to_none=True)
        disc_loss.backward()
        pending = self.step_phi(self.phi_opt)

        reward = diayn_reward(log_q.detach(), self.prior.dim, discrete, self.cfg.diayn)
        info = self.sac_update(b, reward, pending)
        info.update(
            phi_loss=disc_loss.detach(), lam=self.log_lambda.exp().detach(), reward=reward.mean(), w_mean=torch.ones(())
        )
        return info
