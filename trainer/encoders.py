"""Observation encoders in front of φ, Q and π: identity for state vectors, a CNN for pixels.

The CNN is the reference's: 4 convolutions (kernel 4, stride 2; 48, 96, 192, 384 channels; ELU),
flattened (1536 features for 64×64 inputs). The reference gives φ, each Q and π a CNN of their own
("separate"); "shared" gives all of them one CNN, trained by φ's and the critics' losses and read
by π without gradient (as SAC from pixels usually does), the critics' target keeping a Polyak copy.
docs/envs.md says which one collie uses and why (`benchmarks/bench_encoders.py` measures it).
"""

from __future__ import annotations

import torch
from torch import nn

CNN_CHANNELS = (48, 96, 192, 384)


class PixelEncoder(nn.Module):
    """(…, C, H, W) images in [0, 1] → (…, out_dim) features. `copies` > 1 runs that many independent
    CNNs as one grouped convolution (the twin critics) and returns (copies, B, out_dim)."""

    def __init__(self, obs_shape: tuple[int, ...], copies: int = 1) -> None:
        super().__init__()
        channels, height, width = obs_shape
        layers: list[nn.Module] = []
        inp = channels
        for out in CNN_CHANNELS:
            layers += [nn.Conv2d(inp * copies, out * copies, kernel_size=4, stride=2, groups=copies), nn.ELU()]
            inp = out
        self.net = nn.Sequential(*layers)
        self.copies = copies
        with torch.no_grad():
            self.out_dim = self.net(torch.zeros(1, channels * copies, height, width)).numel() // copies

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        batch = obs.reshape(-1, *obs.shape[-3:])
        if self.copies == 1:
            return self.net(batch).flatten(1).reshape(*obs.shape[:-3], self.out_dim)
        features = self.net(batch.repeat(1, self.copies, 1, 1))  # copy i reads channel group i
        return features.reshape(len(batch), self.copies, self.out_dim).transpose(0, 1)


def deterministic_convolutions() -> None:
    """cuDNN's deterministic convolution algorithms, none picked by timing: a seed's pixel run on a
    GPU, and its resume, give the same numbers (TF32 convolutions stay on, torch's default;
    docs/training.md, "On a GPU"). Nothing changes on the CPU."""
    torch.backends.cudnn.deterministic = True
    torch.backends.cudnn.benchmark = False


def is_pixels(obs_shape: int | tuple[int, ...]) -> bool:
    return not isinstance(obs_shape, int) and len(obs_shape) == 3


def feature_dim(obs_shape: int | tuple[int, ...]) -> int:
    """Width of what φ, Q and π see after their encoder."""
    if is_pixels(obs_shape):
        return PixelEncoder(tuple(obs_shape)).out_dim  # type: ignore[arg-type]  # a tuple here: pixel observations
    return obs_shape if isinstance(obs_shape, int) else int(obs_shape[0])


def join(features: torch.Tensor, *rest: torch.Tensor) -> torch.Tensor:
    """Concatenate encoder features with (B, ·) inputs, broadcasting those over the twin critics'
    leading axis when the features have one."""
    if features.dim() == 3:
        rest = tuple(r.expand(features.shape[0], *r.shape) for r in rest)
    return torch.cat([features, *rest], dim=-1)
