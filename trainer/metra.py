"""METRA with COLLIE's guidance weight — one gradient step, readable top to bottom.

Per gradient step, on a batch (s, a, z, s′) from the replay buffer B (Algorithm 1, lines 9–13):
  1. φ ascends  J^φ = E[ w·(φ(s′) − φ(s))ᵀz + λ·min(ε, 1 − ‖φ(s′) − φ(s)‖²) ]        (Eq. 9)
  2. λ descends J^λ = E[ λ·min(ε, 1 − ‖φ(s′) − φ(s)‖²) ]  (through log λ)              (Eq. 10)
  3. SAC on the intrinsic reward r(s, z, s′) = w·(φ(s′) − φ(s))ᵀz                        (Eq. 11)
     with twin Q, target y = r + γ(min Q̄(s′, z, a′) − α log π(a′|s′, z)), learned α.
METRA is w ≡ 1; the Oracle baseline takes w from the task rule; COLLIE takes w from Eq. 8.
The constraint is on the *sum* of squared latent differences (‖Δφ‖₂ ≤ 1, as the paper writes).
Rewards are never stored: they are recomputed from φ every time a transition is sampled.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from trainer.config import Config
from trainer.encoders import PixelEncoder, feature_dim, is_pixels
from trainer.fast_ops import fast_ops_pay
from trainer.networks import SkillLatent, TanhGaussianPolicy, TwinQ, init_like_reference
from trainer.optim import adam, restore_kernel, step_together
from trainer.skills import SkillPrior

# weight_fn(φ(s), φ(s′)) → w, shape (B,); both arguments detached.
WeightFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def guided_reward(projection: torch.Tensor, w: torch.Tensor, form: str = "multiplicative") -> torch.Tensor:
    """r = w·(φ(s′) − φ(s))ᵀz (Eq. 11); the additive ablation (Appendix F) r = (φ(s′) − φ(s))ᵀz + w."""
    return projection + w if form == "additive" else w * projection


@dataclass
class TorchBatch:
    obs: torch.Tensor  # normalised s
    next_obs: torch.Tensor  # normalised s′
    action: torch.Tensor
    skill: torch.Tensor  # z as fed to π and Q
    direction: torch.Tensor  # the vector multiplying Δφ (z, or centred one-hot)


class Metra:
    def __init__(
        self, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, cfg: Config, device: torch.device
    ) -> None:
        """`obs_shape`: the state dimension, or (C, H, W) for pixels (then CNN encoders, per cfg.encoder)."""
        self.cfg, self.prior, self.device = cfg, prior, device
        k, h, n = prior.dim, cfg.hidden, cfg.layers
        f = feature_dim(obs_shape)
        enc = self._encoders(obs_shape, cfg.encoder)
        fast = fast_ops_pay(device) if cfg.fast_ops is None else cfg.fast_ops
        self.phi = SkillLatent(f, k, h, n, enc["phi"])
        self.qf = TwinQ(f + k + action_dim, h, n, enc["qf"], fast)
        self.qf_target = TwinQ(f + k + action_dim, h, n, enc["qf_target"], fast)
        self.policy = TanhGaussianPolicy(
            f + k,
            action_dim,
            h,
            n,
            enc["policy"],
            detach_encoder=cfg.encoder == "shared",
            log_std_min=cfg.log_std_min,
            fast=fast,
        )
        if cfg.init == "reference":
            init_like_reference(self.phi, self.qf, self.policy)
        for net in (self.phi, self.qf, self.qf_target, self.policy):  # initialised on the CPU: a seed's
            net.to(device)  # weights are the same on every device
        self.qf_target.load_state_dict(self.qf.state_dict())
        self.qf_target.requires_grad_(False)
        self.learn_alpha = True  # DIAYN's reference variant keeps α fixed
        self.log_alpha = torch.tensor(np.log(cfg.alpha_init), device=device, requires_grad=True)
        self.log_lambda = torch.tensor(np.log(cfg.lambda_init), device=device, requires_grad=True)
        self.target_entropy = cfg.target_entropy_scale * action_dim
        self.phi_opt = adam(self.phi.parameters(), cfg.lr, cfg.fused_adam)
        self.qf_opt = adam(self.qf.parameters(), cfg.lr, cfg.fused_adam)
        self.policy_opt = adam(self.policy.parameters(), cfg.lr, cfg.fused_adam)
        self.alpha_opt = adam([self.log_alpha], cfg.lr, cfg.fused_adam)
        self.lambda_opt = adam([self.log_lambda], cfg.lr, cfg.fused_adam)
        self.phi_version = 0  # bumped by every φ step; keys the labelled-embedding cache
        # SAC never reads φ unless a pixel encoder is shared: then φ's step may wait for π's and
        # run in the same Adam call (bit-identical; one call's overhead instead of two).
        self.phi_apart = not (is_pixels(obs_shape) and cfg.encoder == "shared")

    @staticmethod
    def _encoders(obs_shape: int | tuple[int, ...], kind: str) -> dict[str, torch.nn.Module | None]:
        """Each network's encoder: none for states; for pixels one CNN per network (twin critics: a
        grouped pair), or one CNN shared by φ, Q and π with the target critic's own copy."""
        if not is_pixels(obs_shape):
            return dict.fromkeys(("phi", "qf", "qf_target", "policy"))
        shape = tuple(obs_shape)  # type: ignore[arg-type]  # a tuple here: pixel observations
        if kind == "shared":
            shared = PixelEncoder(shape)
            return {"phi": shared, "qf": shared, "qf_target": PixelEncoder(shape), "policy": shared}
        return {
            "phi": PixelEncoder(shape),
            "qf": PixelEncoder(shape, copies=2),
            "qf_target": PixelEncoder(shape, copies=2),
            "policy": PixelEncoder(shape),
        }

    def compile(self) -> None:
        """`--compile`: torch.compile each network's forward in place (its backward follows through
        AOTAutograd; state-dict keys are unchanged). The optimiser steps stay eager (`--fused-adam`
        is their fast kernel), as do the losses between the networks. Off by default: on the 2-core
        CPU it stepped no faster, busy or quiet (docs/training.md, `make bench-update`)."""
        for net in (self.phi, self.qf, self.qf_target, self.policy):
            net.compile()

    # ---- acting ---------------------------------------------------------------------------
    @torch.inference_mode()
    def act(self, obs: torch.Tensor, skill: torch.Tensor, deterministic: bool) -> torch.Tensor:
        return self.policy.act(obs, skill, deterministic)

    # ---- learning ------------------------------------------------------------------------
    def update(self, b: TorchBatch, weight_fn: WeightFn | None) -> dict[str, torch.Tensor]:
        """One gradient step of φ, λ and SAC (Eqs. 9–11). Returns detached diagnostics."""
        lam = self.log_lambda.exp().detach()
        phi_both = self.phi(torch.cat([b.obs, b.next_obs]))
        phi_s, phi_next = phi_both.chunk(2)
        delta = phi_next - phi_s
        w = torch.ones_like(delta[:, 0]) if weight_fn is None else weight_fn(phi_s.detach(), phi_next.detach())
        projection = (delta * b.direction).sum(-1)  # (φ(s′) − φ(s))ᵀz
        penalty = torch.clamp(1.0 - delta.pow(2).sum(-1), max=self.cfg.epsilon)  # min(ε, 1 − ‖Δφ‖²)

        guided = guided_reward(projection, w, self.cfg.reward_form)
        phi_loss = -(guided + lam * penalty).mean()  # Eq. 9, ascended
        lambda_loss = self.log_lambda * penalty.detach().mean()  # Eq. 10: λ rises while violated
        # φ's and log λ's losses touch disjoint parameters (λ is detached in one, the penalty in the
        # other): one backward pass gives each exactly the gradient of its own loss.
        self.phi_opt.zero_grad(set_to_none=True)
        self.lambda_opt.zero_grad(set_to_none=True)
        (phi_loss + lambda_loss).backward()
        pending = self.step_phi(self.phi_opt, self.lambda_opt)

        reward = guided.detach()  # Eq. 11
        info = self.sac_update(b, reward, pending)
        info.update(
            phi_loss=phi_loss.detach(),
            lambda_loss=lambda_loss.detach(),
            lam=lam,
            constraint=delta.detach().pow(2).sum(-1).mean(),
            w_mean=w.mean(),
            reward=reward.mean(),
        )
        return info

    def step_phi(self, *opts: torch.optim.Adam) -> tuple[torch.optim.Adam, ...]:
        """φ's (and λ's) Adam step after their backward: now, or (`phi_apart`) handed back for
        `sac_update` to run with π's. Either way φ has stepped when `update` returns."""
        self.phi_version += 1
        if self.phi_apart:
            return opts
        step_together(*opts)
        return ()

    def sac_update(
        self, b: TorchBatch, reward: torch.Tensor, pending: tuple[torch.optim.Adam, ...] = ()
    ) -> dict[str, torch.Tensor]:
        """Soft actor-critic on a given reward: twin Q, learned α, Polyak-averaged target.
        Episodes never terminate (time limit only), so no done mask, as the reference.
        `pending`: optimisers with gradients ready whose parameters SAC does not read (φ, λ),
        stepped in π's Adam call."""
        alpha = self.log_alpha.exp().detach()
        with torch.no_grad():
            next_action, next_logp = self.policy.sample(b.next_obs, b.skill)
            q_next = self.qf_target(b.next_obs, b.skill, next_action).min(0).values
            target = reward + self.cfg.gamma * (q_next - alpha * next_logp)
        q = self.qf(b.obs, b.skill, b.action)
        qf_loss = 0.5 * (q - target).pow(2).mean(1).sum()
        self.qf_opt.zero_grad(set_to_none=True)
        qf_loss.backward()
        self.qf_opt.step()

        action, logp = self.policy.sample(b.obs, b.skill)
        self.qf.requires_grad_(False)  # actor gradients flow through Q to the action only
        q_pi = self.qf(b.obs, b.skill, action).min(0).values
        self.qf.requires_grad_(True)
        policy_loss = (alpha * logp - q_pi).mean()
        # α's loss reads log π detached and π's reads α detached: one backward pass serves both.
        actor_loss = policy_loss
        self.policy_opt.zero_grad(set_to_none=True)
        if self.learn_alpha:
            actor_loss = actor_loss - (self.log_alpha * (logp.detach() + self.target_entropy)).mean()
            self.alpha_opt.zero_grad(set_to_none=True)
        actor_loss.backward()
        step_together(self.policy_opt, *([self.alpha_opt] if self.learn_alpha else []), *pending)

        with torch.no_grad():  # Polyak averaging, one multi-tensor op
            torch._foreach_lerp_(list(self.qf_target.parameters()), list(self.qf.parameters()), self.cfg.tau)
        return dict(
            qf_loss=qf_loss.detach(),
            policy_loss=policy_loss.detach(),
            alpha=alpha,
            q=q.detach().mean(),
            entropy=-logp.detach().mean(),
        )

    # ---- checkpoints ---------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            name: getattr(self, name).state_dict()
            for name in (
                "phi",
                "qf",
                "qf_target",
                "policy",
                "phi_opt",
                "qf_opt",
                "policy_opt",
                "alpha_opt",
                "lambda_opt",
            )
        } | {
            "log_alpha": self.log_alpha.detach().clone(),
            "log_lambda": self.log_lambda.detach().clone(),
            "phi_version": self.phi_version,
        }

    def load_state_dict(self, state: dict) -> None:
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
            self.log_lambda.copy_(state["log_lambda"])
        for name in ("phi", "qf", "qf_target", "policy", "phi_opt", "qf_opt", "policy_opt", "alpha_opt", "lambda_opt"):
            getattr(self, name).load_state_dict(state[name])
        for opt in (self.phi_opt, self.qf_opt, self.policy_opt, self.alpha_opt, self.lambda_opt):
            restore_kernel(opt, self.cfg.fused_adam)
        self.phi_version = int(state["phi_version"])
