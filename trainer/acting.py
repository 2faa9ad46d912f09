"""The rollout's acting path: π(a | s, z) for a few states per step with the fewest torch calls.

For a batch of 8 states a 2×256 policy costs less in arithmetic than in dispatch: the module
forward (cat, Linear, Tanh, chunk, clamp, exp, randn_like, tanh) plus the numpy→torch→numpy
conversions around it. `Actor` evaluates the same weights (views of the parameters, so build one
per rollout) into preallocated buffers: the observation is normalised straight into the input
buffer that already holds the skills (no cat), each layer is one addmm into its own buffer and an
in-place tanh, and the Gaussian's few numbers are finished in numpy. The noise is torch.randn of
the rows' shape from torch's global generator, the same draw as TanhGaussianPolicy.act's
randn_like, so for the same seed the actions equal the policy's own to float tolerance
(tests/core/test_acting.py); not bit for bit (numpy's exp/tanh are not torch's), so a run's
rollouts are deterministic per seed and across a resume, but differ at float level from
`TorchActor`'s. Anything else (a CNN encoder, another device) acts through `Metra.act` (`TorchActor`).

`--acting torch` (`acting_path`) makes every rollout act through `TorchActor`, as all runs did before
2026-12-01 (18403cf): those runs' seeds are then reproduced exactly. Which path acts changes only
rounding, and through it each seed's trajectories: on the point mass's Range Oracle six seeds of each
gave the same figures within one std (docs/results.md, "Which acting path").
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np
import torch
from torch import nn

from trainer.metra import Metra
from trainer.networks import LOG_STD_MAX, TanhGaussianPolicy


class Normalising(Protocol):
    mean: np.ndarray
    std: np.ndarray

    def __call__(self, obs: np.ndarray) -> np.ndarray: ...


class Acting(Protocol):
    def __call__(self, obs: np.ndarray, rows: slice, out: np.ndarray) -> None:
        """Write the actions for the raw observations `obs` of env rows `rows` into `out`."""


class TorchActor:
    """The general path: normalise, `Metra.act` on the agent's device, back to numpy."""

    def __init__(self, agent: Metra, skills: np.ndarray, normalise: Normalising, deterministic: bool) -> None:
        self.agent, self.normalise, self.deterministic = agent, normalise, deterministic
        self.skills = torch.as_tensor(skills, dtype=torch.float32, device=agent.device)

    def __call__(self, obs: np.ndarray, rows: slice, out: np.ndarray) -> None:
        o = torch.as_tensor(self.normalise(obs), device=self.agent.device)
        out[:] = self.agent.act(o, self.skills[rows], self.deterministic).cpu().numpy()


class Actor:
    """The state-vector MLP policy on the CPU, evaluated with addmm into preallocated buffers."""

    def __init__(self, agent: Metra, skills: np.ndarray, normalise: Normalising, deterministic: bool) -> None:
        if not fits(agent):
            raise ValueError("Actor needs a CPU policy without an encoder whose trunk is Linear/Tanh layers")
        policy = agent.policy
        linears = [m for m in policy.trunk if isinstance(m, nn.Linear)]
        self.n, self.obs_dim = len(skills), linears[0].in_features - skills.shape[1]
        # detached views of the parameters (as F.linear multiplies): no autograd, and an optimiser
        # step or load_state_dict (both in place) is seen by the next call
        self.weights = [(m.weight.detach().t(), m.bias.detach()) for m in linears]
        self.widths = [linears[0].in_features, *(m.out_features for m in linears)]
        self.action_dim = linears[-1].out_features // 2
        self.skills = np.asarray(skills, np.float32)
        self.mean, self.std = np.asarray(normalise.mean, np.float32), np.asarray(normalise.std, np.float32)
        self.log_std_min, self.deterministic = policy.log_std_min, deterministic
        self.groups: dict[tuple[int, int, int], _Buffers] = {}

    def __call__(self, obs: np.ndarray, rows: slice, out: np.ndarray) -> None:
        key = rows.indices(self.n)
        b = self.groups.get(key) or self.groups.setdefault(key, _Buffers(self, rows))
        np.subtract(obs, self.mean, out=b.s)  # (s − μ) / σ, as Normaliser
        np.divide(b.s, self.std, out=b.s)
        x, last = b.x, len(self.weights) - 1
        for i, ((w, bias), h) in enumerate(zip(self.weights, b.hidden, strict=True)):
            torch.addmm(bias, x, w, out=h)
            if i < last:
                h.tanh_()
            x = h
        if self.deterministic:
            np.tanh(b.mean, out=out)
            return
        b.noise.normal_()  # torch.randn's draw, from the global generator
        t = b.tail  # tanh(μ + exp(clip(log σ)) · ε), in place
        np.maximum(b.log_std, self.log_std_min, out=t)
        np.minimum(t, LOG_STD_MAX, out=t)
        np.exp(t, out=t)
        np.multiply(t, b.noise_np, out=t)
        np.add(b.mean, t, out=t)
        np.tanh(t, out=out)


class _Buffers:
    """One row group's own tensors, allocated fresh and contiguous: addmm's float result for a row
    depends on where its input sits in memory (a view at an odd row offset rounds differently), so
    each group computes exactly as a batch of its rows alone would."""

    def __init__(self, actor: Actor, rows: slice) -> None:
        m = len(range(*rows.indices(actor.n)))
        self.x = torch.empty(m, actor.widths[0])
        x = self.x.numpy()
        x[:, actor.obs_dim :] = actor.skills[rows]
        self.s = x[:, : actor.obs_dim]
        self.hidden = [torch.empty(m, w) for w in actor.widths[1:]]
        y, a = self.hidden[-1].numpy(), actor.action_dim
        self.mean, self.log_std = y[:, :a], y[:, a:]
        self.noise = torch.empty(m, a)
        self.noise_np = self.noise.numpy()
        self.tail = np.empty((m, a), np.float32)


def fits(agent: Metra) -> bool:
    """Whether `Actor` can evaluate this agent's policy."""
    p = getattr(agent, "policy", None)
    if not isinstance(p, TanhGaussianPolicy):
        return False
    layers = list(p.trunk)
    return (
        agent.device.type == "cpu"
        and isinstance(p.encoder, nn.Identity)
        and all(isinstance(m, nn.Linear | nn.Tanh) for m in layers)
        and [isinstance(m, nn.Linear) for m in layers] == [i % 2 == 0 for i in range(len(layers))]
    )


def actor(agent: Metra, skills: np.ndarray, normalise: Normalising, deterministic: bool) -> Acting:
    """`Actor` wherever it fits the agent's policy, else the general torch path."""
    cls = Actor if fits(agent) else TorchActor
    return cls(agent, skills, normalise, deterministic)


ActingFactory = Callable[[Metra, np.ndarray, Normalising, bool], Acting]
PATHS: dict[str, ActingFactory] = {"fast": actor, "torch": TorchActor}  # Config.acting's names (ACTING_PATHS)


def acting_path(name: str) -> ActingFactory:
    """The rollouts' acting path by its config name (`Config.acting`)."""
    if name not in PATHS:
        raise ValueError(f"unknown acting path {name!r}; valid: {', '.join(PATHS)}")
    return PATHS[name]
