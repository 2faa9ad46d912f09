"""make bench-gpu: the `paper` preset on a CUDA GPU, Ant and pixel Quadruped, a few epochs each.

Per env: updates/s of COLLIE's update at its costliest, the end of a run (`with_full_labels`: the
whole label budget, N_total segments of H states, and guidance at full strength, so every step
re-encodes all labelled states, pixels through the CNN), env steps/s of the training rollouts, the
seconds of one 48-episode evaluation, peak GPU memory, and the projected wall time of a full paper
run (Ant 10 000 epochs, Quadruped 5 000): epochs × (rollout + update time per epoch) plus
(epochs / eval_every) evaluations; an upper bound, since the label set grows over the run and w ≡ 1
before the first session. `--method metra` times METRA's update instead. Without CUDA it prints
`no CUDA device (torch <version> built …)` and exits 0 (`--device cpu --preset smoke` runs the
same code on the CPU, as the test suite does).
JSON (runs/bench/gpu.json): per env updates_per_s, env_steps_per_s, eval_s, peak_gpu_mb,
peak_gpu_reserved_mb, epoch_s, projected_hours, epochs_full, grad_steps, labelled_states; plus device, preset and
method (also the file's settings, with the timed epochs). Without CUDA it writes nothing: a
machine without a GPU must not overwrite a GPU's figures.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import tempfile
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import torch
from gpu_sync import settled
from record import record

from trainer.config import make_config
from trainer.loop import Trainer


def with_full_labels(t: Trainer) -> None:
    """COLLIE's costliest step: N_total segments of H states from the collected trajectories,
    labelled bad, neutral, good in turn (the step's cost depends on how many states are labelled,
    not on which label they carry), and β = 0 (guidance at full strength)."""
    c = t.cfg
    slots, starts = t.replay.sample_windows(c.total_queries, c.segment_length, np.random.default_rng(0))
    for q, (i, s) in enumerate(zip(slots, starts, strict=True)):
        t.labelled.set(f"bench-{q}", t.replay.obs[i, s : s + c.segment_length], q % 3)
    t.first_feedback_epoch = t.epoch - c.n_sessions * c.feedback_every  # β_e = max(0, 1 − k_β) = 0


def bench_env(env: str, preset: str, device: str, epochs: int, method: str) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        full = make_config(preset, env)
        per_epoch = full.episodes_per_epoch * full.episode_steps
        cfg = make_config(preset, env, method=method, out=tmp, device=device, start_transitions=per_epoch)
        t = Trainer(cfg, progress=False)
        t._t0 = time.perf_counter()
        dev = t.device
        if dev.type == "cuda":  # the env before's trainer gone (a reference cycle holds it until collected)
            gc.collect()
            torch.cuda.empty_cache()
            torch.cuda.reset_peak_memory_stats(dev)
        t.epoch += 1
        t.collect_epoch()
        if method == "collie":
            with_full_labels(t)
            assert t.beta() == 0.0
        t.train_epoch()  # warm-up: the allocator's pools, lazy CUDA modules
        settled(dev)
        collect_s = train_s = 0.0
        for _ in range(epochs):
            t.epoch += 1
            start = time.perf_counter()
            t.collect_epoch()
            mid = time.perf_counter()
            t.train_epoch()
            settled(dev)
            collect_s, train_s = collect_s + mid - start, train_s + time.perf_counter() - mid
        start = time.perf_counter()
        t.evaluate()
        eval_s = time.perf_counter() - start
        epoch_s = (collect_s + train_s) / epochs
        return {
            "updates_per_s": epochs * cfg.grad_steps / train_s,
            "env_steps_per_s": epochs * per_epoch / collect_s,
            "eval_s": eval_s,
            "epoch_s": epoch_s,
            "peak_gpu_mb": torch.cuda.max_memory_allocated(dev) / 1e6 if dev.type == "cuda" else 0.0,
            # what the allocator held at most (its cache included; the CUDA context is not): the GPU's memory needed
            "peak_gpu_reserved_mb": torch.cuda.max_memory_reserved(dev) / 1e6 if dev.type == "cuda" else 0.0,
            "epochs_full": full.epochs,
            "grad_steps": cfg.grad_steps,
            "projected_hours": (full.epochs * epoch_s + full.epochs / full.eval_every * eval_s) / 3600,
            "labelled_states": t.labelled.n_states(),
        }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", default="ant,quadruped")
    p.add_argument("--epochs", type=int, default=5, help="timed epochs per env (after one warm-up epoch)")
    p.add_argument("--preset", default="paper")
    p.add_argument("--device", default="cuda")
    p.add_argument("--method", default="collie", choices=("collie", "metra"), help="whose update is timed")
    a = p.parse_args()
    device = torch.device("cuda" if a.device == "auto" else a.device)  # a GPU's benchmark: auto is cuda
    if device.type == "cuda" and not torch.cuda.is_available():
        built = f"built for CUDA {torch.version.cuda}" if torch.version.cuda else "built without CUDA"
        print(f"no CUDA device (torch {torch.__version__} {built})")
        return 0
    if device.type == "cuda" and (device.index or 0) >= torch.cuda.device_count():
        print(
            f"bench-gpu: --device {a.device}: this machine has {torch.cuda.device_count()} CUDA devices",
            file=sys.stderr,
        )
        return 2
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu"
    print(f"bench-gpu on {name}, preset {a.preset}, {a.method}'s update, {a.epochs} timed epochs per env")
    figures: dict[str, object] = {"device": name, "preset": a.preset, "method": a.method}
    for env in a.envs.split(","):
        r = bench_env(env, a.preset, str(device), a.epochs, a.method)
        figures[env] = r
        print(
            f"  {env:10s} {r['updates_per_s']:8.1f} updates/s ({r['labelled_states']} labelled states)  "
            f"{r['env_steps_per_s']:8.0f} env steps/s  "
            f"eval {r['eval_s']:6.1f} s  peak {r['peak_gpu_mb']:8.0f} MB  → a full run of {r['epochs_full']} "
            f"epochs ≈ {r['projected_hours']:.1f} h"
        )
    record("gpu", figures, {"device": name, "preset": a.preset, "method": a.method, "epochs": a.epochs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
