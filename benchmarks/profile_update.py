"""Where a full COLLIE update's CPU time goes, one thread (`make profile-update`): torch.profiler over
`--steps` steps of bench_update's full step (800 labelled states, Ant) at width `--hidden`.

JSON (runs/bench/profile_update_<hidden>.json): `matmul_share` (self CPU time in addmm, bmm,
baddbmm and mm ÷ the total), `adam_share` (the Adam steps' own Python and kernels, inclusive), and
`top` (the ten ops with the most self CPU time, in µs per step), all under the profiler, which
slows the step (`step_ms_profiled`: its CPU ms per step); `step_ms_unprofiled` (the same step
without it). `adam_one_by_one_ms` and
`adam_together_ms`: the update's five Adam steps (φ, λ, Q, π, α) on the same gradients, each with
its own `step()` and in one `step_together` call (the trainer makes two calls: Q, then the rest).
Settings: hidden, steps.
"""

from __future__ import annotations

import argparse

import torch
from bench_update import timed, update_setup
from record import record
from torch.profiler import ProfilerActivity, profile

from trainer.metra import Metra
from trainer.optim import step_together

MATMULS = ("aten::addmm", "aten::bmm", "aten::baddbmm", "aten::mm")


def adam_timings(agent: Metra, steps: int = 200) -> dict[str, float]:
    """The five optimisers stepped on the gradients the last update left (re-stepping them only
    moves the weights of a benchmark agent)."""
    opts = (agent.phi_opt, agent.lambda_opt, agent.qf_opt, agent.policy_opt, agent.alpha_opt)
    for opt in opts:  # the last update stepped with these grads; set_to_none cleared none of them since
        assert all(p.grad is not None for g in opt.param_groups for p in g["params"])

    def one_by_one() -> None:
        for opt in opts:
            opt.step()

    return {
        "adam_one_by_one_ms": 1e3 / timed(one_by_one, steps),
        "adam_together_ms": 1e3 / timed(lambda: step_together(*opts), steps),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hidden", type=int, default=256, help="MLP width")
    p.add_argument("--steps", type=int, default=50, help="profiled gradient steps")
    args = p.parse_args()
    torch.set_num_threads(1)
    agent, full, _, _ = update_setup("ant", args.hidden, torch.device("cpu"))
    timed(full, 10)  # warm-up: first-call costs out of the profile
    unprofiled_ms = 1e3 / timed(full, args.steps)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(args.steps):
            full()
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events)
    matmul = sum(e.self_cpu_time_total for e in events if e.key in MATMULS)
    adam = sum(
        e.cpu_time_total for e in events if e.key.startswith(("Optimizer.step#Adam", "Optimizer.step#step_together"))
    )
    top = sorted(events, key=lambda e: e.self_cpu_time_total, reverse=True)[:10]
    figures = {
        "step_ms_profiled": total / args.steps / 1e3,
        "matmul_share": matmul / total,
        "adam_share": adam / total,
        "top": {e.key: e.self_cpu_time_total / args.steps for e in top},
        "step_ms_unprofiled": unprofiled_ms,
        **adam_timings(agent),
    }
    print(f"2×{args.hidden} full update, one thread: {figures['step_ms_profiled']:.1f} ms of CPU per step (profiled)")
    print(f"  matmuls {figures['matmul_share']:.0%}, Adam steps {figures['adam_share']:.0%}")
    print(f"  without the profiler: {unprofiled_ms:.1f} ms per step")
    print(
        f"  the five Adam steps: {figures['adam_one_by_one_ms']:.2f} ms one by one, "
        f"{figures['adam_together_ms']:.2f} ms in one call"
    )
    for name, us in figures["top"].items():
        print(f"  {name:<40} {us:8.0f} µs/step")
    record(f"profile_update_{args.hidden}", figures, {"hidden": args.hidden, "steps": args.steps})


if __name__ == "__main__":
    main()
