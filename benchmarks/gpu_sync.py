"""A clock around GPU work reads it only once the GPU is done: kernels are queued, not run, when a
call returns. A no-op on the CPU."""

from __future__ import annotations

import torch


def settled(device: torch.device | None = None) -> None:
    """Wait for `device`'s queued kernels (the current GPU's when None, as torch.cuda.synchronize)."""
    if (device is None or device.type == "cuda") and torch.cuda.is_available():
        torch.cuda.synchronize(device)
