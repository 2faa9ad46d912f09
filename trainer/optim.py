"""Adam as every learner builds it: which kernel runs the step.

`foreach` (the default) updates all of an optimiser's tensors with multi-tensor ops: the same
arithmetic, in the same order, as torch's per-tensor loop, so runs are bit-identical to it.
`fused` (`--fused-adam true`) runs one kernel per parameter that reads and writes each element
once; on the CPU it is several times faster for small nets, but it rounds differently (≈ 1 ulp
per step), so a run is deterministic per seed yet not bit-identical to a `foreach` one.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch


def adam(params: Iterable[torch.nn.Parameter] | list[torch.Tensor], lr: float, fused: bool) -> torch.optim.Adam:
    choice = kernel(fused)
    return torch.optim.Adam(params, lr=lr, foreach=choice["foreach"], fused=choice["fused"])


def kernel(fused: bool) -> dict[str, bool | None]:
    return {"fused": True, "foreach": None} if fused else {"fused": None, "foreach": True}


def restore_kernel(opt: torch.optim.Optimizer, fused: bool) -> None:
    """A loaded optimiser state carries the saving run's kernel choice (or none, from older
    checkpoints); the run's configuration decides which kernel steps from here on."""
    for group in opt.param_groups:
        group.update(kernel(fused))
