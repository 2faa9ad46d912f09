"""The three function approximators of METRA/COLLIE: the skill latent φ, twin Q and a tanh-Gaussian
policy. MLP sizes follow Table 5 (2 hidden layers; 1024 units in the paper preset). Each reads the
observation through an optional encoder (encoders.py: a CNN for pixels), so checkpoints, target
copies and optimisers carry it along with the network that owns it.

Initialisation (`--init reference`, the default) follows the reference's garage modules: zero
biases; Xavier-uniform weights for φ and the policy's hidden layers, Xavier-normal for the policy's
output layer and every layer of the Q networks. `--init torch` keeps PyTorch's default
(Kaiming-uniform, a = √5). Pixel CNN encoders keep their own initialisation either way."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import torch
from torch import nn
from torch.nn import functional as F

from trainer.encoders import join

LOG_STD_MIN, LOG_STD_MAX = math.log(1e-6), 2.0  # the reference's floor (min_std 1e-6) and cap (max_std e²)


class _TanhViaSigmoid(torch.autograd.Function):
    """tanh(x) = 2σ(2x) − 1, with tanh's own backward from the output (1 − y²)."""

    @staticmethod
    def forward(ctx: torch.autograd.function.FunctionCtx, x: torch.Tensor) -> torch.Tensor:
        y = torch.sigmoid(2 * x).mul_(2).sub_(1)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx: torch.autograd.function.FunctionCtx, grad: torch.Tensor) -> torch.Tensor:
        (y,) = ctx.saved_tensors  # type: ignore[attr-defined]  # set by save_for_backward; not in the stub
        return torch.ops.aten.tanh_backward(grad, y)


class Tanh(nn.Tanh):
    """nn.Tanh computed as 2σ(2x) − 1: on some CPUs torch's tanh is several times slower than its
    sigmoid (not on all: trainer/fast_ops.py measures it), and the policy trunk runs it on every
    hidden unit (`make bench-update`: `tanh_speedup_<h>`, forward and backward).
    Equal to torch.tanh within 2e-7 (float32 rounding near 0.5 inside σ)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return _TanhViaSigmoid.apply(x)


def relu_in_place() -> nn.ReLU:
    """ReLU writing over its input, a Linear's output, which that Linear's backward does not read:
    the same values and gradients without a fresh activation buffer per layer."""
    return nn.ReLU(inplace=True)


def mlp(inp: int, hidden: int, layers: int, out: int, act: Callable[[], nn.Module] = relu_in_place) -> nn.Sequential:
    mods: list[nn.Module] = []
    width = inp
    for _ in range(layers):
        mods += [nn.Linear(width, hidden), act()]
        width = hidden
    mods.append(nn.Linear(width, out))
    return nn.Sequential(*mods)


class SkillLatent(nn.Module):
    """φ: S → Z, the Lipschitz-constrained skill latent (Eq. 6's constraint, enforced by Eq. 10)."""

    def __init__(
        self, obs_dim: int, skill_dim: int, hidden: int, layers: int, encoder: nn.Module | None = None
    ) -> None:
        super().__init__()
        self.encoder = encoder or nn.Identity()
        self.net = mlp(obs_dim, hidden, layers, skill_dim)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(self.encoder(obs))


class EnsembleLinear(nn.Module):
    """`n` independent linear layers evaluated in one batched matmul (twin Q as one call). With
    `fast`, a one-output layer is a multiply-and-sum instead: on some CPUs bmm's matrix-vector product
    is several times slower (trainer/fast_ops.py) (`make bench-update`: `one_output_speedup_<h>`)."""

    def __init__(self, n: int, inp: int, out: int, fast: bool = True) -> None:
        super().__init__()
        self.fast = fast
        bound = 1.0 / math.sqrt(inp)  # nn.Linear's default init, per member
        self.weight = nn.Parameter(torch.empty(n, inp, out).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(n, 1, out).uniform_(-bound, bound))

    @torch.no_grad()
    def xavier_normal_(self) -> None:
        """Each member's weight ~ N(0, 2 / (fan_in + fan_out)), bias 0 (garage's MLP default)."""
        inp, out = self.weight.shape[1:]
        self.weight.normal_(0.0, math.sqrt(2.0 / (inp + out)))
        self.bias.zero_()

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # x: (n, B, inp) or (B, inp)
        if self.fast and self.weight.shape[2] == 1:
            return (x * self.weight.transpose(1, 2)).sum(-1, keepdim=True) + self.bias
        if x.dim() == 2:
            x = x.unsqueeze(0).expand(self.weight.shape[0], -1, -1)
        return torch.baddbmm(self.bias, x, self.weight)


class TwinQ(nn.Module):
    """Q1, Q2 (s, z, a) → R, clipped double-Q as in SAC. `inp` counts encoder features + |z| + |A|;
    the encoder returns (B, F) features (shared by both) or (2, B, F) (one CNN each)."""

    def __init__(self, inp: int, hidden: int, layers: int, encoder: nn.Module | None = None, fast: bool = True) -> None:
        super().__init__()
        self.encoder = encoder or nn.Identity()
        dims = [inp] + [hidden] * layers + [1]
        self.layers = nn.ModuleList(EnsembleLinear(2, a, b, fast) for a, b in itertools.pairwise(dims))

    def forward(self, obs: torch.Tensor, skill: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Returns (2, B) Q-values."""
        x = join(self.encoder(obs), skill, action)
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < len(self.layers) - 1:
                x = F.relu_(x)  # in place, as relu_in_place
        return x.squeeze(-1)


class TanhGaussianPolicy(nn.Module):
    """π(a | s, z): tanh-squashed Gaussian with a tanh trunk (as the reference). `inp` counts encoder
    features + |z|. With `detach_encoder` the policy reads an encoder that others train; with `fast`
    the trunk's tanh is `Tanh` (2σ(2x) − 1), else torch's."""

    def __init__(
        self,
        inp: int,
        action_dim: int,
        hidden: int,
        layers: int,
        encoder: nn.Module | None = None,
        detach_encoder: bool = False,
        log_std_min: float = LOG_STD_MIN,
        fast: bool = True,
    ) -> None:
        super().__init__()
        self.encoder = encoder or nn.Identity()
        self.detach_encoder = detach_encoder
        self.log_std_min = log_std_min
        self.trunk = mlp(inp, hidden, layers, 2 * action_dim, act=Tanh if fast else nn.Tanh)

    def forward(self, obs: torch.Tensor, skill: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        with torch.set_grad_enabled(torch.is_grad_enabled() and not self.detach_encoder):
            features = self.encoder(obs)
        mean, log_std = self.trunk(join(features, skill)).chunk(2, dim=-1)
        return mean, log_std.clamp(self.log_std_min, LOG_STD_MAX)

    def sample(self, obs: torch.Tensor, skill: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Reparameterised action in (−1, 1) and its log-probability (tanh change of variables)."""
        mean, log_std = self(obs, skill)
        std = log_std.exp()
        u = mean + std * torch.randn_like(mean)
        log_prob = (-0.5 * ((u - mean) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        log_prob = log_prob - (2 * (math.log(2) - u - F.softplus(-2 * u))).sum(-1)
        return torch.tanh(u), log_prob

    def act(self, obs: torch.Tensor, skill: torch.Tensor, deterministic: bool) -> torch.Tensor:
        """An action for acting in the env (no log-probability needed)."""
        mean, log_std = self(obs, skill)
        if deterministic:
            return torch.tanh(mean)
        return torch.tanh(mean + log_std.exp() * torch.randn_like(mean))


@torch.no_grad()
def _xavier(layer: nn.Linear, normal: bool) -> None:
    (nn.init.xavier_normal_ if normal else nn.init.xavier_uniform_)(layer.weight)
    nn.init.zeros_(layer.bias)


@torch.no_grad()
def init_like_reference(phi: nn.Module, qf: TwinQ, policy: TanhGaussianPolicy) -> None:
    """Re-initialise the MLP layers as the reference's garage modules do (see the module docstring).
    φ: every nn.Linear outside its encoder; the policy: its trunk; Q: its ensemble layers."""
    for name, module in phi.named_modules():
        if isinstance(module, nn.Linear) and not name.startswith("encoder"):
            _xavier(module, normal=False)
    linears = [m for m in policy.trunk if isinstance(m, nn.Linear)]
    for layer in linears[:-1]:
        _xavier(layer, normal=False)
    _xavier(linears[-1], normal=True)
    for ensemble in qf.layers:
        assert isinstance(ensemble, EnsembleLinear)
        ensemble.xavier_normal_()
