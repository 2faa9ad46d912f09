"""LSD (Park et al., 2022): distance-maximising skill discovery with the Euclidean distance —
the LSD baseline of Section 5.1 and, with COLLIE's w, the COLLIE-L2 ablation (`--distance l2`).

METRA constrains ‖φ(s′) − φ(s)‖ ≤ 1 (temporal distance) through the dual variable λ (Eqs. 9–10).
LSD instead makes φ 1-Lipschitz in the Euclidean distance of (normalised) states,
    ‖φ(s) − φ(s′)‖ ≤ ‖s − s′‖₂    (the DSD constraint with d(x, y) = ‖x − y‖₂),
by spectral normalisation of every linear layer (ReLU is 1-Lipschitz), so there is no dual step.
Per gradient step, on a batch (s, a, z, s′):
  1. φ ascends  J^φ = E[ w·(φ(s′) − φ(s))ᵀz ]                 (Eq. 9 without the λ term)
  2. SAC on     r(s, z, s′) = w·(φ(s′) − φ(s))ᵀz               (Eq. 11)
w ≡ 1 for LSD; COLLIE-L2 takes w from Eq. 8 exactly as COLLIE does (`Trainer.weight_fn`).
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn.utils.parametrizations import spectral_norm

from trainer.config import Config
from trainer.encoders import feature_dim, is_pixels
from trainer.metra import Metra, TorchBatch, WeightFn, guided_reward
from trainer.networks import SkillLatent
from trainer.optim import adam
from trainer.skills import SkillPrior


def lipschitz_latent(obs_dim: int, skill_dim: int, hidden: int, layers: int) -> SkillLatent:
    """φ with every linear layer spectrally normalised: a 1-Lipschitz map in ‖·‖₂."""
    phi = SkillLatent(obs_dim, skill_dim, hidden, layers)
    for i, module in enumerate(phi.net):
        if isinstance(module, nn.Linear):
            phi.net[i] = spectral_norm(module)
    return phi


class Lsd(Metra):
    def __init__(
        self, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, cfg: Config, device: torch.device
    ) -> None:
        if is_pixels(obs_shape):
            raise ValueError("LSD's Lipschitz φ (and COLLIE-L2) is for state observations, not pixels")
        super().__init__(obs_shape, action_dim, prior, cfg, device)
        self.phi = lipschitz_latent(feature_dim(obs_shape), prior.dim, cfg.hidden, cfg.layers).to(device)
        self.phi_opt = adam(self.phi.parameters(), cfg.lr, cfg.fused_adam)

    def update(self, b: TorchBatch, weight_fn: WeightFn | None) -> dict[str, torch.Tensor]:
        """One φ step on J^φ (no constraint term: φ is Lipschitz by construction), then SAC."""
        phi_s, phi_next = self.phi(torch.cat([b.obs, b.next_obs])).chunk(2)
        delta = phi_next - phi_s
        w = torch.ones_like(delta[:, 0]) if weight_fn is None else weight_fn(phi_s.detach(), phi_next.detach())
        projection = (delta * b.direction).sum(-1)  # (φ(s′) − φ(s))ᵀz
        objective = guided_reward(projection, w, self.cfg.reward_form)

        phi_loss = -objective.mean()
        self.phi_opt.zero_grad(set_to_none=True)
        phi_loss.backward()
        pending = self.step_phi(self.phi_opt)

        reward = objective.detach()  # Eq. 11
        info = self.sac_update(b, reward, pending)
        info.update(
            phi_loss=phi_loss.detach(),
            lam=self.log_lambda.exp().detach(),
            constraint=delta.detach().pow(2).sum(-1).mean(),
            w_mean=w.mean(),
            reward=reward.mean(),
        )
        return info
