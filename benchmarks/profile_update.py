"""Where a full COLLIE update's CPU time goes, one thread (`make profile-update`): torch.profiler over
`--steps` steps of bench_update's full step (800 labelled states, Ant) at width `--hidden`.

JSON (runs/bench/profile_update_<hidden>.json): `matmul_share` (self CPU time in addmm, bmm,
baddbmm and mm ÷ the total), `adam_share` (the Adam steps' own Python and kernels, inclusive), and
`top` (the ten ops with the most self CPU time, in µs per step)."""

from __future__ import annotations

import argparse

import torch
from bench_update import timed, update_setup
from record import record
from torch.profiler import ProfilerActivity, profile

MATMULS = ("aten::addmm", "aten::bmm", "aten::baddbmm", "aten::mm")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hidden", type=int, default=256, help="MLP width")
    p.add_argument("--steps", type=int, default=50, help="profiled gradient steps")
    args = p.parse_args()
    torch.set_num_threads(1)
    _, full, _, _ = update_setup("ant", args.hidden, torch.device("cpu"))
    timed(full, 10)  # warm-up: first-call costs out of the profile
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(args.steps):
            full()
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events)
    matmul = sum(e.self_cpu_time_total for e in events if e.key in MATMULS)
    adam = sum(e.cpu_time_total for e in events if e.key.startswith("Optimizer.step#Adam"))
    top = sorted(events, key=lambda e: e.self_cpu_time_total, reverse=True)[:10]
    figures = {
        "hidden": args.hidden,
        "steps": args.steps,
        "step_ms": total / args.steps / 1e3,
        "matmul_share": matmul / total,
        "adam_share": adam / total,
        "top": {e.key: e.self_cpu_time_total / args.steps for e in top},
    }
    print(f"2×{args.hidden} full update, one thread: {figures['step_ms']:.1f} ms of CPU per step")
    print(f"  matmuls {figures['matmul_share']:.0%}, Adam steps {figures['adam_share']:.0%}")
    for name, us in figures["top"].items():
        print(f"  {name:<40} {us:8.0f} µs/step")
    record(f"profile_update_{args.hidden}", figures)


if __name__ == "__main__":
    main()
