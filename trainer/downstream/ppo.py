"""PPO (Schulman et al., 2017) for the high-level controller of the hierarchical downstream task
(Appendix E, Table 7): a categorical policy over the frozen skills and a value function, trained
on whole episodes of options, readable top to bottom.

Per iteration: run `envs` episodes (each `options_per_episode` high-level steps), compute
generalised advantage estimates, then `update_epochs` passes of minibatch updates on
    L = −E[min(ρ·Â, clip(ρ, 1 − ε, 1 + ε)·Â)] + c_v·E[(V − R̂)²] − c_H·E[H(π)],  ρ = π/π_old.
Episodes have a fixed length and end with the time limit: the last option does not bootstrap.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical

from trainer.downstream.goal import GoalOptions
from trainer.networks import mlp


@dataclass
class PpoConfig:
    iterations: int = 9000  # Table 7's epochs (8 episodes each); the CPU budget in docs/results.md is far lower
    envs: int = 8  # episodes per iteration
    lr: float = 1e-4  # Table 7
    hidden: int = 1024  # Table 7: 2 × 1024
    layers: int = 2
    gamma: float = 0.99  # per option
    gae_lambda: float = 0.95
    clip: float = 0.2
    update_epochs: int = 10
    minibatches: int = 4
    entropy_coef: float = 0.01
    value_coef: float = 0.5
    max_grad_norm: float = 0.5


class ActorCritic(nn.Module):
    def __init__(self, obs_dim: int, n_actions: int, hidden: int, layers: int) -> None:
        super().__init__()
        self.actor = mlp(obs_dim, hidden, layers, n_actions, act=nn.Tanh)
        self.critic = mlp(obs_dim, hidden, layers, 1, act=nn.Tanh)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def policy(self, obs: torch.Tensor) -> Categorical:
        return Categorical(logits=self.actor(obs))


def gae(rewards: torch.Tensor, values: torch.Tensor, gamma: float, lam: float) -> torch.Tensor:
    """Generalised advantage estimates for (T, n) rewards and values of fixed-length episodes."""
    advantages = torch.zeros_like(rewards)
    last = torch.zeros_like(rewards[0])
    for t in reversed(range(len(rewards))):
        next_value = values[t + 1] if t + 1 < len(rewards) else torch.zeros_like(values[t])
        delta = rewards[t] + gamma * next_value - values[t]
        last = delta + gamma * lam * last
        advantages[t] = last
    return advantages


def train_ppo(
    env: GoalOptions, cfg: PpoConfig, seed: int = 0, log: Callable[[int, float], None] | None = None
) -> tuple[ActorCritic, list[float]]:
    """Train the high-level controller; returns it and the mean episode return of every iteration."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = ActorCritic(env.obs_dim, env.n_skills, cfg.hidden, cfg.layers)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, eps=1e-5)
    steps, n = env.options_per_episode, env.n
    curve: list[float] = []
    for it in range(cfg.iterations):
        # ---- collect one episode per env ----
        obs = torch.zeros(steps, n, env.obs_dim)
        actions = torch.zeros(steps, n, dtype=torch.long)
        logps, values, rewards = torch.zeros(steps, n), torch.zeros(steps, n), torch.zeros(steps, n)
        o = torch.as_tensor(env.reset(rng))
        for t in range(steps):
            with torch.no_grad():
                dist = net.policy(o)
                a = dist.sample()
                obs[t], actions[t], logps[t], values[t] = o, a, dist.log_prob(a), net.value(o)
            next_o, r = env.step(a.numpy())
            rewards[t] = torch.as_tensor(r, dtype=torch.float32)
            o = torch.as_tensor(next_o)
        curve.append(float(rewards.sum(0).mean()))
        if log is not None:
            log(it, curve[-1])
        # ---- PPO update ----
        adv = gae(rewards, values, cfg.gamma, cfg.gae_lambda)
        returns = adv + values
        b_obs, b_act, b_logp = obs.reshape(-1, env.obs_dim), actions.reshape(-1), logps.reshape(-1)
        b_adv, b_ret = adv.reshape(-1), returns.reshape(-1)
        size = len(b_obs)
        mb = max(1, size // cfg.minibatches)
        for _ in range(cfg.update_epochs):
            for idx in torch.randperm(size).split(mb):
                dist = net.policy(b_obs[idx])
                ratio = (dist.log_prob(b_act[idx]) - b_logp[idx]).exp()
                a_mb = b_adv[idx]
                a_mb = (a_mb - a_mb.mean()) / (a_mb.std() + 1e-8) if len(idx) > 1 else a_mb
                policy_loss = -torch.min(ratio * a_mb, ratio.clamp(1 - cfg.clip, 1 + cfg.clip) * a_mb).mean()
                value_loss = (net.value(b_obs[idx]) - b_ret[idx]).pow(2).mean()
                loss = policy_loss + cfg.value_coef * value_loss - cfg.entropy_coef * dist.entropy().mean()
                opt.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(net.parameters(), cfg.max_grad_norm)
                opt.step()
    return net, curve


def evaluate(env: GoalOptions, choose: Callable[[np.ndarray], np.ndarray], episodes: int, seed: int) -> np.ndarray:
    """Returns of `episodes` goal episodes (in batches of env.n) with high-level rule `choose(obs)`."""
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []
    while sum(len(r) for r in out) < episodes:
        o, total = env.reset(rng), np.zeros(env.n)
        for _ in range(env.options_per_episode):
            o, r = env.step(choose(o))
            total += r
        out.append(total)
    return np.concatenate(out)[:episodes]


def greedy(net: ActorCritic) -> Callable[[np.ndarray], np.ndarray]:
    def choose(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net.actor(torch.as_tensor(obs)).argmax(-1).numpy()

    return choose
