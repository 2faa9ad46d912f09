"""Adam as every learner builds it: which kernel runs the step.

`fused` (the default since 2026-12-05) runs one kernel per parameter that reads and writes each
element once; on the CPU it is several times faster than the multi-tensor ops for small nets.
`foreach` (`--fused-adam false`) updates all of an optimiser's tensors with multi-tensor ops: the
same arithmetic, in the same order, as torch's per-tensor loop, so runs are bit-identical to it and
to every run before 2026-12-05. The two round differently (≈ 1 ulp per step): each is deterministic
per seed, but a fused run is not bit-identical to a foreach one.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch
from torch.optim.adam import adam as adam_step


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


# Every hyper-parameter Adam's functional step reads from a group; optimisers stepped together must agree on all.
_SHARED = (
    "lr",
    "betas",
    "eps",
    "weight_decay",
    "amsgrad",
    "maximize",
    "foreach",
    "fused",
    "capturable",
    "differentiable",
    "decoupled_weight_decay",
)


@torch.no_grad()
def step_together(*opts: torch.optim.Adam) -> None:
    """One Adam step of several optimisers in a single multi-tensor call.

    Adam is elementwise and each tensor keeps its own moments and step count, so the arithmetic per
    element is exactly that of calling each `opt.step()` (the tests check bit-equality); what it
    saves is the per-call Python (hooks, grouping): about a fifth of the five Adam steps of a 2×256
    update on the 2-core CPU (`make profile-update`: keys `adam_one_by_one_ms`, `adam_together_ms`;
    figures in docs/results.md). Each optimiser keeps its own state, so checkpoints are unchanged.
    Optimisers whose groups differ in any hyper-parameter are stepped one by one."""
    groups = [(opt, group) for opt in opts for group in opt.param_groups]
    first = groups[0][1]
    if any(group[k] != first[k] for _, group in groups for k in _SHARED):
        for opt in opts:
            opt.step()
        return
    with torch.profiler.record_function("Optimizer.step#step_together"):  # as torch names its steps
        _one_call(opts, first)


def _one_call(opts: tuple[torch.optim.Adam, ...], first: dict) -> None:
    params: list[torch.Tensor] = []
    grads: list[torch.Tensor] = []
    exp_avgs: list[torch.Tensor] = []
    exp_avg_sqs: list[torch.Tensor] = []
    max_exp_avg_sqs: list[torch.Tensor] = []
    steps: list[torch.Tensor] = []
    has_complex = False
    for opt in opts:
        for group in opt.param_groups:
            # private, but the very call Adam.step makes to create and gather each tensor's state
            has_complex |= opt._init_group(group, params, grads, exp_avgs, exp_avg_sqs, max_exp_avg_sqs, steps)
    beta1, beta2 = first["betas"]
    adam_step(
        params,
        grads,
        exp_avgs,
        exp_avg_sqs,
        max_exp_avg_sqs,
        steps,
        amsgrad=first["amsgrad"],
        has_complex=has_complex,
        beta1=beta1,
        beta2=beta2,
        lr=first["lr"],
        weight_decay=first["weight_decay"],
        eps=first["eps"],
        maximize=first["maximize"],
        foreach=first["foreach"],
        capturable=first["capturable"],
        differentiable=first["differentiable"],
        fused=first["fused"],
        decoupled_weight_decay=first["decoupled_weight_decay"],
    )
