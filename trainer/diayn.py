"""DIAYN (Eysenbach et al., 2019) on collie's SAC — the mutual-information baseline of Section 5.1.

Per gradient step, on a batch (s, a, z, s′):
  1. the skill discriminator q(z | s′) ascends  E[log q(z | s′)]
  2. SAC on the intrinsic reward  r(s, z, s′) = log q(z | s′) − log p(z)
The discriminator is the network METRA calls φ (same shape, S → R^dim z), so checkpoints, the
labelled-embedding cache and evaluation need nothing new:
  one-hot skills:      q(z | s) = softmax(φ(s))_z,      log p(z) = −log D
  continuous skills:   q(z | s) = N(z; φ(s), I),        log q = −½‖z − φ(s)‖² − (D/2)·log 2π
On the unit sphere p(z) is uniform, so −log p(z) is a constant and is left out of the reward.
DIAYN asks for no labels: the guidance weight is ignored (w ≡ 1) and λ is never used.
"""

from __future__ import annotations

import math

import torch
from torch.nn import functional as F

from trainer.metra import Metra, TorchBatch, WeightFn


def skill_log_likelihood(logits_or_mean: torch.Tensor, z: torch.Tensor, discrete: bool) -> torch.Tensor:
    """log q(z | s′) from the discriminator output: categorical for one-hot z, unit Gaussian otherwise."""
    if discrete:
        return (F.log_softmax(logits_or_mean, dim=-1) * z).sum(-1)
    k = z.shape[-1]
    return -0.5 * (z - logits_or_mean).pow(2).sum(-1) - 0.5 * k * math.log(2 * math.pi)


def diayn_reward(log_q: torch.Tensor, dim: int, discrete: bool) -> torch.Tensor:
    """r = log q(z | s′) − log p(z); −log p(z) = log D for a uniform one-hot prior, 0 on the sphere."""
    return log_q + math.log(dim) if discrete else log_q


class Diayn(Metra):
    def update(self, b: TorchBatch, weight_fn: WeightFn | None) -> dict[str, torch.Tensor]:
        """One discriminator step, then SAC on r = log q(z | s′) − log p(z). `weight_fn` is ignored."""
        discrete = self.prior.discrete
        log_q = skill_log_likelihood(self.phi(b.next_obs), b.skill, discrete)
        disc_loss = -log_q.mean()
        self.phi_opt.zero_grad(set_to_none=True)
        disc_loss.backward()
        self.phi_opt.step()
        self.phi_version += 1

        reward = diayn_reward(log_q.detach(), self.prior.dim, discrete)
        info = self.sac_update(b, reward)
        info.update(
            phi_loss=disc_loss.detach(), lam=self.log_lambda.exp().detach(), reward=reward.mean(), w_mean=torch.ones(())
        )
        return info
