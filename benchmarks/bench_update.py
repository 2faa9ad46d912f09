"""make bench-update: the trainer's inner costs as ratios measured in one run (machines are noisy;
absolute numbers are printed for context only). Every part below runs by default, the two
training-run parts (7, 8) included. JSON: runs/bench/update.json; with `--only` the parts asked
for, in PARTS order, name the file instead (`--only flops --only update`: update-update-flops.json),
so a partial run never overwrites the whole one. Settings: env, threads, device.

1. Update cost: gradient steps/s of the full paper-size update (φ + λ + SAC + w with 800
   labelled states, 2×1024 MLPs, batch 256) beside a plain SAC update of the same networks and
   METRA's update (w ≡ 1). Keys `full_steps_per_s`, `sac_steps_per_s`, `metra_steps_per_s`,
   `cost_ratio` (goal ≤ 1.3), and `cost_ratio_flops`: the same ratio in FLOPs, what the step costs
   when every matmul runs at one rate (the floor of `cost_ratio` for the same mathematics);
   `metra_cost_ratio_flops`: METRA's step (w ≡ 1: no labelled states to encode) ÷ SAC's, in FLOPs.
2. Update FLOP rate: the FLOPs of one full update (counted by torch's FlopCounterMode, forward and
   backward; key `update_gflop_<h>`) times its steps/s, ÷ this machine's rate for a (256 × h)·(h × h)
   matmul, one thread, for h = 256 and 1024. Keys `update_gflops_<h>`, `matmul_gflops_<h>`,
   `flop_fraction_<h>` (goal ≥ 0.6); `flop_fraction_foreach_<h>` the same with `--fused-adam false`,
   `flop_fraction_before_<h>` with `--fused-adam false --fast-ops false` (the step before 12-05);
   `flop_fraction_fast_ops_on_<h>` / `_off_<h>`: the default with `--fast-ops` forced on / off
   (`fast_ops_default`: whether this machine's default turns them on, trainer/fast_ops.py; only
   the one that differs from the default is timed, the other is `flop_fraction_<h>`);
   `matmuls_alone_fraction_<h>`: the step's own matmuls (same shapes and strides) replayed with
   nothing else, ÷ the same matmul rate — the ceiling of `flop_fraction_<h>` were all other work free.
   Compiled (`--compile`, skipped with --no-compile): `compile_s_<h>` (the first steps' extra time,
   i.e. compilation), `compile_speedup_<h>` (compiled ÷ eager steps/s, measured interleaved) and
   `compile_break_even_steps_<h>` (steps before the compile time is paid back; inf if never).
3. Rollouts: an 8-episode rollout with the `cpu`-preset policy (threads as the trainer runs it by
   default: one group, its mujoco.batch call on 2 MuJoCo threads) ÷ a single-thread raw `mj_step`
   loop over the same model, and the same rollout with serial physics and with 2 physics threads
   pipelined with the policy. Keys
   `rollout_fraction_<env>`, `rollout_fraction_serial_<env>`, `rollout_fraction_pipelined_<env>`,
   `rollout_steps_per_s_<env>`, `raw_steps_per_s_<env>` for ant and half_cheetah (goal ≥ 0.9);
   `rollout_fraction_torch_<env>`: the default rollout acting through the general torch path
   (`TorchActor`) instead of `Actor`, what the fast acting path gains; `rollout_fraction_batch2_<env>`:
   serial, but each step's mujoco.batch call on 2 MuJoCo threads (`batch_threads=2`, bit-identical
   rollouts). Where the default rollout's time goes, each part timed alone over one episode, µs
   per step of all 8 envs: `rollout_step_us_<env>` (the whole rollout), `policy_us_<env>` (the
   `actor` path acting for the 8 rows), `physics_us_<env>` (`VectorEnv.step`), `raw_us_<env>` (the
   raw loop's time for 8 env steps); `physics_threads_<env>` and `batch_threads_<env>`: the
   default rollout's groups and MuJoCo threads. `--only rollout` runs just this part.
4. Device data path: 32 batches gathered, normalised and made tensors by the device path
   (trainer/device_replay.py) ÷ the host path it replaced (numpy gather, normalise, as_tensor).
   Key `device_sampling_ratio` (≤ 1: costs nothing on the CPU).
5. Checkpoints: a periodic checkpoint of an Ant `cpu` run (replay holding 200 trajectories, 25
   epochs of new ones since the last checkpoint). Keys `checkpoint_s` (goal < 1), `checkpoint_mb`
   (bytes written, goal < 50), `replay_mb` (the whole replay, what a checkpoint used to rewrite).
6. Kernels (`--fast-ops`; trainer/fast_ops.py's measurement, which decides their default, with ten
   times its passes), one thread, forward and backward on a batch of 256
   at width h = 256 and 1024: `tanh_speedup_<h>` (torch.tanh's time ÷ `Tanh`'s, 2σ(2x) − 1) and
   `one_output_speedup_<h>` (the twin Q's one-output layer by bmm ÷ by multiply-sum), with the
   times in µs (`tanh_us_<h>`, `fast_tanh_us_<h>`, `one_output_bmm_us_<h>`, `one_output_fast_us_<h>`);
   `fast_ops_default` as in 2; `fast_ops_measure_s`: the seconds the first run on a host spends on
   that measurement (trainer/fast_ops.py).
7. A trained agent's update (`--flush-denormal`, trainer/denormals.py): a point `cpu` COLLIE run
   trained `--aged-epochs` epochs (key `aged_epochs`) without flushing, resumed twice, each copy's epoch of updates
   timed alternately with and without flushing denormals. Keys `aged_denormals` (values of the
   agent's state below float32's smallest normal, mostly Adam's moments of dead units),
   `aged_update_s_kept` / `aged_update_s_flushed` (median s per epoch), `flush_denormal_speedup`
   (kept ÷ flushed), `aged_denormals_after` (left in the flushing copy after its epochs).
8. A whole run (`--only whole` alone): a point `cpu` COLLIE run of `--whole-epochs` epochs (key
   `whole_run_epochs`; the preset's 400) without and then with flushing denormals. Keys `whole_run_s_kept`,
   `whole_run_s_flushed` (wall s, rollouts and evaluations included), `whole_run_speedup`.
"""

from __future__ import annotations

import argparse
import gc
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch
from gpu_sync import settled
from record import record
from torch._ops import OpOverload
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils.flop_counter import FlopCounterMode

from trainer.acting import TorchActor, actor
from trainer.config import make_config
from trainer.device_replay import DeviceReplay
from trainer.envs import VectorEnv, make_env
from trainer.fast_ops import fast_ops_pay, measure, measure_choice
from trainer.guidance import LabelledSets, guidance_weight
from trainer.loop import Trainer
from trainer.metra import Metra, TorchBatch
from trainer.replay import FIELDS, TrajectoryReplay
from trainer.rollout import Normaliser, rollout
from trainer.skills import SkillPrior
from trainer.threads import resolve_threads


def timed(fn: Callable[[], None], steps: int) -> float:
    settled()
    start = time.perf_counter()
    for _ in range(steps):
        fn()
    settled()
    return steps / (time.perf_counter() - start)


Step = Callable[[], None]


def update_setup(env_name: str, hidden: int, dev: torch.device, **options: bool) -> tuple[Metra, Step, Step, Step]:
    """The agent and three steps on fixed batches: full COLLIE, plain SAC, METRA (w ≡ 1).
    `options`: Config fields such as fused_adam=True or compile=True."""
    env = make_env(env_name)
    cfg = make_config("paper", env_name, hidden=hidden, **options)
    prior = SkillPrior(cfg.skill_dim, cfg.discrete_skills)
    agent = Metra(env.obs_dim, env.action_dim, prior, cfg, dev)
    if cfg.compile:
        agent.compile()
    rng = np.random.default_rng(0)
    b = cfg.batch_size

    def batch() -> TorchBatch:
        z = torch.as_tensor(prior.sample(b, rng), device=dev)
        obs = torch.randn(b, env.obs_dim, device=dev)
        return TorchBatch(
            obs,
            obs + 0.1 * torch.randn_like(obs),
            torch.rand(b, env.action_dim, device=dev) * 2 - 1,
            z,
            torch.as_tensor(prior.reward_direction(z.cpu().numpy()), device=dev),
        )

    labelled = LabelledSets(lambda x: x, dev)
    for q in range(40):  # N_total = 40 segments × H = 20 states
        labelled.set(f"q{q}", rng.normal(size=(20, env.obs_dim)).astype(np.float32), q % 3)
    batches = [batch() for _ in range(8)]
    it = iter(range(10**9))

    def full() -> None:
        def w(_s: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
            return guidance_weight(n, labelled.embeddings(agent.phi, agent.phi_version))

        agent.update(batches[next(it) % 8], w)

    def plain_sac() -> None:
        agent.sac_update(batches[next(it) % 8], torch.randn(b, device=dev))

    def metra() -> None:
        agent.update(batches[next(it) % 8], None)

    # The imports' objects out of the collector's reach: a full collection walking them inside a
    # timed block made that block read slow. A training run's full collections happen during its
    # imports, so the timed steps should not pay for one either.
    gc.freeze()
    return agent, full, plain_sac, metra


def flops(step: Step) -> int:
    with FlopCounterMode(display=False) as counter:
        step()
    return counter.get_total_flops()


class MatmulRecorder(TorchDispatchMode):
    """Keeps every matmul a step makes, with copies of its arguments (same shapes and strides)."""

    OPS = (
        torch.ops.aten.mm.default,
        torch.ops.aten.addmm.default,
        torch.ops.aten.bmm.default,
        torch.ops.aten.baddbmm.default,
    )

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[tuple[OpOverload, list[Any], dict[str, Any]]] = []

    def __torch_dispatch__(
        self, func: OpOverload, types: Any, args: tuple[Any, ...] = (), kwargs: dict[str, Any] | None = None
    ) -> Any:
        if func in self.OPS:  # clone keeps a dense tensor's strides; as_strided restores an expanded one's
            copies = [
                a.detach().clone().as_strided(a.shape, a.stride()) if isinstance(a, torch.Tensor) else a for a in args
            ]
            self.calls.append((func, copies, kwargs or {}))
        return func(*args, **(kwargs or {}))


def matmuls_alone(step: Step) -> Step:
    """The matmuls of one call of `step`, replayed with nothing between them."""
    with MatmulRecorder() as recorder:
        step()
    calls = recorder.calls

    def replay() -> None:
        for func, args, kwargs in calls:
            func(*args, **kwargs)

    return replay


def bench_update(env_name: str, steps: int, rounds: int) -> dict[str, float]:
    dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    _, full, plain_sac, metra = update_setup(env_name, 1024, dev)
    steps_fns = {"full": full, "sac": plain_sac, "metra": metra}
    for fn in steps_fns.values():
        timed(fn, 3)  # warm-up
    rates: dict[str, list[float]] = {k: [] for k in steps_fns}
    for _ in range(rounds):  # interleaved, so all see the same machine load
        for k, fn in steps_fns.items():
            rates[k].append(timed(fn, steps))
    med = {k: float(np.median(v)) for k, v in rates.items()}
    _, full_counted, sac_counted, metra_counted = update_setup(env_name, 1024, dev, fast_ops=False)  # every matmul
    counted_full, counted_sac, counted_metra = flops(full_counted), flops(sac_counted), flops(metra_counted)
    return {
        "full_steps_per_s": med["full"],
        "sac_steps_per_s": med["sac"],
        "metra_steps_per_s": med["metra"],
        "cost_ratio": med["sac"] / med["full"],
        "cost_ratio_flops": counted_full / counted_sac,
        "metra_cost_ratio_flops": counted_metra / counted_sac,
    }


def bench_flops(env_name: str, steps: int, rounds: int, compiled: bool) -> dict[str, float]:
    """One thread, CPU: the update's FLOP rate against a plain matmul of the same width; the eager
    default, the default with foreach Adam, the step as it was before 12-05 (foreach Adam, torch's
    tanh, bmm for the one-output Q layer) and (if `compiled`) `--compile`, timed interleaved. FLOPs
    are counted on the before-12-05 step, whose every matmul torch's counter sees (the same
    mathematics; the multiply-sum layer would go uncounted)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    cpu = torch.device("cpu")
    default_on = fast_ops_pay(cpu)
    out: dict[str, float] = {"fast_ops_default": float(default_on)}
    same, other = ("fast_ops_on", "fast_ops_off") if default_on else ("fast_ops_off", "fast_ops_on")
    try:
        for h in (256, 1024):
            variants = {
                "eager": update_setup(env_name, h, cpu)[1],
                "foreach": update_setup(env_name, h, cpu, fused_adam=False)[1],
                "before": update_setup(env_name, h, cpu, fused_adam=False, fast_ops=False)[1],
                other: update_setup(env_name, h, cpu, fast_ops=not default_on)[1],  # the default is `same`
            }
            flop = flops(variants["before"])
            variants["matmuls"] = matmuls_alone(variants["eager"])
            first: dict[str, float] = {}
            if compiled:
                variants["compiled"] = update_setup(env_name, h, cpu, compile=True)[1]
            for k, fn in variants.items():  # the first 3 steps; for "compiled" they include compilation
                first[k] = 3 / timed(fn, 3)
            a, w = torch.randn(256, h), torch.randn(h, h)
            mm_rate: list[float] = []
            rates: dict[str, list[float]] = {k: [] for k in variants}
            for _ in range(rounds):
                mm_rate.append(timed(lambda a=a, w=w: torch.mm(a, w), 20) * 2 * 256 * h * h)
                for k, fn in variants.items():
                    rates[k].append(timed(fn, steps))
            med = {k: float(np.median(v)) for k, v in rates.items()}
            med[same] = med["eager"]
            out[f"update_gflop_{h}"] = flop / 1e9
            out[f"update_gflops_{h}"] = med["eager"] * flop / 1e9
            out[f"matmul_gflops_{h}"] = float(np.median(mm_rate)) / 1e9
            out[f"flop_fraction_{h}"] = out[f"update_gflops_{h}"] / out[f"matmul_gflops_{h}"]
            for k in ("foreach", "before", "fast_ops_on", "fast_ops_off"):
                out[f"flop_fraction_{k}_{h}"] = med[k] * flop / 1e9 / out[f"matmul_gflops_{h}"]
            mm_flop = flops(variants["matmuls"])
            out[f"matmuls_alone_fraction_{h}"] = med["matmuls"] * mm_flop / 1e9 / out[f"matmul_gflops_{h}"]
            if compiled:
                saved = 1 / med["eager"] - 1 / med["compiled"]  # seconds per step
                out[f"compile_s_{h}"] = first["compiled"] - 3 / med["compiled"]
                out[f"compile_speedup_{h}"] = med["compiled"] / med["eager"]
                out[f"compile_break_even_steps_{h}"] = out[f"compile_s_{h}"] / saved if saved > 0 else float("inf")
    finally:
        torch.set_num_threads(threads)
    return out


def raw_mj_step_rate(env_name: str, steps: int, seed: int) -> float:
    """Env steps/s of one thread looping mj_step over one env's model (random controls)."""
    env = make_env(env_name, seed=seed)
    env.reset()
    controls = np.random.default_rng(seed).uniform(-1, 1, size=(steps, env.action_dim))
    m, d, skip = env.model, env.data, env.frame_skip
    start = time.perf_counter()
    for u in controls:
        d.ctrl[:] = u
        mujoco.mj_step(m, d, nstep=skip)
    return steps / (time.perf_counter() - start)


def rollout_parts(env: VectorEnv, agent: Metra, skills: np.ndarray, norm: Normaliser, seed: int) -> tuple[float, float]:
    """Seconds per step of the default rollout's two parts, each alone over one episode: the
    policy acting for every row (as `rollout` calls it, one torch thread) and the physics."""
    b = env.reset(list(range(seed, seed + env.num_envs)))
    policy, obs = actor(agent, skills, norm, deterministic=False), b.obs.copy()
    actions, every, steps = np.zeros((env.num_envs, env.action_dim), np.float32), slice(None), env.episode_steps
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        start = time.perf_counter()
        for _ in range(steps):
            policy(obs, every, actions)
        acting = time.perf_counter() - start
        start = time.perf_counter()
        for _ in range(steps):
            env.step(actions, out=b)
        physics = time.perf_counter() - start
    finally:
        torch.set_num_threads(threads)
    return acting / steps, physics / steps


def bench_rollout(env_name: str, rounds: int) -> dict[str, float]:
    cfg = make_config("cpu", env_name)
    prior = SkillPrior(cfg.skill_dim, cfg.discrete_skills)
    envs = {
        "default": VectorEnv(env_name, cfg.episodes_per_epoch),  # the default threads
        "torch": VectorEnv(env_name, cfg.episodes_per_epoch),  # the same, acting through TorchActor
        "serial": VectorEnv(env_name, 8, physics_threads=1, batch_threads=1),
        "pipelined": VectorEnv(env_name, 8, physics_threads=2),
        "batch2": VectorEnv(env_name, 8, physics_threads=1, batch_threads=2),  # one group, 2 MuJoCo threads
    }
    default = envs["default"]
    agent = Metra(default.obs_dim, default.action_dim, prior, cfg, torch.device("cpu"))
    norm = Normaliser(default.obs_mean, default.obs_std)
    rng = np.random.default_rng(0)
    n = 8 * default.episode_steps
    rates: dict[str, list[float]] = {kind: [] for kind in (*envs, "raw")}
    parts: dict[str, list[float]] = {"policy": [], "physics": []}
    for r in range(rounds):  # interleaved
        skills = prior.sample(8, rng)
        for kind, env in envs.items():
            start = time.perf_counter()
            acting = TorchActor if kind == "torch" else actor
            rollout(env, agent, skills, list(range(r * 8, r * 8 + 8)), norm, deterministic=False, acting=acting)
            rates[kind].append(n / (time.perf_counter() - start))
        rates["raw"].append(raw_mj_step_rate(env_name, n, r))
        for part, seconds in zip(parts, rollout_parts(default, agent, skills, norm, r * 8), strict=True):
            parts[part].append(seconds)
    med = {k: float(np.median(v)) for k, v in rates.items()}
    for env in envs.values():
        env.close()
    return {
        f"rollout_steps_per_s_{env_name}": med["default"],
        f"raw_steps_per_s_{env_name}": med["raw"],
        f"rollout_fraction_{env_name}": med["default"] / med["raw"],
        f"rollout_fraction_serial_{env_name}": med["serial"] / med["raw"],
        f"rollout_fraction_pipelined_{env_name}": med["pipelined"] / med["raw"],
        f"rollout_fraction_torch_{env_name}": med["torch"] / med["raw"],
        f"rollout_fraction_batch2_{env_name}": med["batch2"] / med["raw"],
        f"physics_threads_{env_name}": default.physics_threads,
        f"batch_threads_{env_name}": default.batch_threads,
        f"rollout_step_us_{env_name}": 8e6 / med["default"],
        f"policy_us_{env_name}": 1e6 * float(np.median(parts["policy"])),
        f"physics_us_{env_name}": 1e6 * float(np.median(parts["physics"])),
        f"raw_us_{env_name}": 8e6 / med["raw"],
    }


def bench_sampling(rounds: int) -> dict[str, float]:
    cfg = make_config("cpu", "ant")
    env = make_env("ant")
    r = TrajectoryReplay(cfg.replay_capacity, 200, env.obs_shape, env.action_dim, cfg.skill_dim, env.nq, env.nv)
    rng = np.random.default_rng(0)
    r.obs[:] = rng.normal(size=r.obs.shape)
    r.count = r.size
    norm, prior, cpu = (
        Normaliser(env.obs_mean, env.obs_std),
        SkillPrior(cfg.skill_dim, cfg.discrete_skills),
        torch.device("cpu"),
    )
    device = DeviceReplay(r, norm, prior.reward_direction, cpu)

    def t(x: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(x, dtype=torch.float32)

    def host() -> None:  # the path the trainer took before
        for _ in range(cfg.grad_steps):
            b = r.sample(cfg.batch_size, rng)
            TorchBatch(t(norm(b.obs)), t(norm(b.next_obs)), t(b.action), t(b.skill), t(prior.reward_direction(b.skill)))

    def on_device() -> None:
        for _ in device.batches(*r.sample_indices(cfg.grad_steps, cfg.batch_size, rng)):
            pass

    host_r, dev_r = [], []
    for _ in range(rounds):
        host_r.append(timed(host, 5))
        dev_r.append(timed(on_device, 5))
    return {"device_sampling_ratio": float(np.median(host_r) / np.median(dev_r))}


def bench_checkpoint() -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        cfg = make_config("cpu", "ant", out=tmp)
        trainer = Trainer(cfg, progress=False)
        trainer._t0 = time.perf_counter()
        r, rng = trainer.replay, np.random.default_rng(0)
        n, t = cfg.episodes_per_epoch, cfg.episode_steps + 1

        def epoch(e: int) -> None:
            r.add(
                rng.normal(size=(n, t, *r.obs.shape[2:])),
                rng.normal(size=(n, t - 1, r.action.shape[2])),
                rng.normal(size=(n, r.skill.shape[1])),
                rng.normal(size=(n, t, 2)),
                rng.normal(size=(n, t)),
                rng.normal(size=(n, t, r.qpos.shape[2])),
                rng.normal(size=(n, t, r.qvel.shape[2])),
                e,
            )

        for e in range(cfg.checkpoint_every):
            epoch(e)
        trainer.checkpoint()
        before = {f: f.stat().st_mtime_ns for f in Path(tmp).rglob("*") if f.is_file()}
        for e in range(cfg.checkpoint_every):
            epoch(cfg.checkpoint_every + e)
        start = time.perf_counter()
        trainer.checkpoint()
        spent = time.perf_counter() - start
        written = [f for f in Path(tmp).rglob("*") if f.is_file() and before.get(f) != f.stat().st_mtime_ns]
        replay_bytes = sum(getattr(r, k)[: r.count].nbytes for k in FIELDS)
        return {
            "checkpoint_s": spent,
            "checkpoint_mb": sum(f.stat().st_size for f in written) / 1e6,
            "replay_mb": replay_bytes / 1e6,
        }


def bench_kernels() -> dict[str, float]:
    """`--fast-ops`'s two kernels against torch's, one thread, batch 256: trainer/fast_ops.py's
    measurement, which decides the default, with ten times its passes; and that default."""
    out: dict[str, float] = {"fast_ops_default": float(fast_ops_pay(torch.device("cpu")))}
    start = time.perf_counter()
    measure_choice()  # what the first run on a host spends deciding
    out["fast_ops_measure_s"] = time.perf_counter() - start
    for h in (256, 1024):
        k = measure(h, repeats=200)
        out.update({f"tanh_us_{h}": k.tanh_us, f"fast_tanh_us_{h}": k.fast_tanh_us})
        out.update({f"one_output_bmm_us_{h}": k.bmm_us, f"one_output_fast_us_{h}": k.fast_one_output_us})
        out.update({f"tanh_speedup_{h}": k.tanh_speedup, f"one_output_speedup_{h}": k.one_output_speedup})
    return out


def denormals(state: Any) -> int:
    """How many values of a (nested) state lie below float32's smallest normal, zero excluded."""
    if isinstance(state, torch.Tensor):
        tiny = torch.finfo(torch.float32).tiny
        return int(((state != 0) & (state.abs() < tiny)).sum()) if state.is_floating_point() else 0
    if isinstance(state, dict):
        return sum(denormals(v) for v in state.values())
    if isinstance(state, list | tuple):
        return sum(denormals(v) for v in state)
    return 0


def bench_aged(epochs: int, rounds: int) -> dict[str, float]:
    """A point `cpu` COLLIE run (oracle labels) trained `epochs` epochs without flushing, then two
    copies of it resumed from its checkpoint, one flushing denormals in its update and one not,
    their epochs' updates timed alternately."""
    with tempfile.TemporaryDirectory() as tmp:
        aged = make_config("cpu", "point", out=f"{tmp}/aged", epochs=epochs, flush_denormal=False)
        Trainer(aged, progress=False).run()
        copies: dict[bool, Trainer] = {}
        for on in (False, True):
            shutil.copytree(aged.out, f"{tmp}/{on}")
            cfg = make_config("cpu", "point", out=f"{tmp}/{on}", epochs=epochs, flush_denormal=on)
            copies[on] = Trainer(cfg, progress=False)
            copies[on].resume()
            copies[on].rebuild_from_source()
        count = denormals(copies[False].agent.state_dict())
        times: dict[bool, list[float]] = {False: [], True: []}
        for _ in range(rounds):
            for on, trainer in copies.items():
                start = time.perf_counter()
                trainer.train_epoch()
                times[on].append(time.perf_counter() - start)
        kept, flushed = float(np.median(times[False])), float(np.median(times[True]))
        return {
            "aged_epochs": epochs,
            "aged_denormals": count,
            "aged_denormals_after": denormals(copies[True].agent.state_dict()),
            "aged_update_s_kept": kept,
            "aged_update_s_flushed": flushed,
            "flush_denormal_speedup": kept / flushed,
        }


def bench_whole_run(epochs: int) -> dict[str, float]:
    """A whole point `cpu` COLLIE run (oracle labels) of `epochs` epochs, without flushing denormals
    and then with, one after the other: their wall times, rollouts and evaluations included."""
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for on, name in ((False, "kept"), (True, "flushed")):
            cfg = make_config("cpu", "point", out=f"{tmp}/{name}", epochs=epochs, flush_denormal=on)
            start = time.perf_counter()
            Trainer(cfg, progress=False).run()
            out[f"whole_run_s_{name}"] = time.perf_counter() - start
    return {
        "whole_run_epochs": epochs,
        **out,
        "whole_run_speedup": out["whole_run_s_kept"] / out["whole_run_s_flushed"],
    }


PARTS = ("update", "flops", "rollout", "sampling", "checkpoint", "kernels", "aged", "whole")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="ant", help="env of the update benchmarks")
    p.add_argument("--steps", type=int, default=10, help="gradient steps per timed block")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--threads", type=int, default=0, help="torch threads (0 = the trainer's default policy)")
    p.add_argument("--aged-epochs", type=int, default=150, help="epochs of the trained agent of part 7 (aged)")
    p.add_argument("--whole-epochs", type=int, default=400, help="epochs of each whole run of part 8 (whole)")
    p.add_argument("--no-compile", action="store_true", help="skip the compiled update (compilation takes minutes)")
    p.add_argument(
        "--only", choices=PARTS, action="append", help="run only these parts (repeatable; JSON: update-<parts>.json)"
    )
    a = p.parse_args()
    parts = [part for part in PARTS if part in (a.only or PARTS)]  # PARTS order: one file name per set
    torch.set_num_threads(resolve_threads(a.threads, 1024))
    dev = "cuda" if torch.cuda.is_available() else "cpu"
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, device {dev}")
    figures: dict[str, float] = {}
    if "update" in parts:
        u = bench_update(a.env, a.steps, a.rounds)
        figures |= u
        print(f"update  ({a.env}, 2×1024, batch 256, 800 labelled states)")
        print(f"  full COLLIE step  {u['full_steps_per_s']:8.1f} steps/s")
        print(f"  plain SAC step    {u['sac_steps_per_s']:8.1f} steps/s")
        print(f"  METRA step (w ≡ 1) {u['metra_steps_per_s']:7.1f} steps/s")
        print(f"  cost ratio        {u['cost_ratio']:8.2f}×   (goal ≤ 1.30×; in FLOPs {u['cost_ratio_flops']:.2f}×)")
        print(f"  METRA's step ÷ SAC's, in FLOPs: {u['metra_cost_ratio_flops']:.2f}× (no labelled states to encode)")
    if "flops" in parts:
        f = bench_flops(a.env, a.steps, a.rounds, compiled=not a.no_compile)
        figures |= f
        for h in (256, 1024):
            print(
                f"  2×{h}: {f[f'update_gflop_{h}']:.3f} GFLOP per update, {f[f'update_gflops_{h}']:.1f} GFLOP/s vs "
                f"matmul {f[f'matmul_gflops_{h}']:.1f} GFLOP/s (one thread) → {100 * f[f'flop_fraction_{h}']:.0f} % "
                f"(goal ≥ 60 %); with foreach Adam {100 * f[f'flop_fraction_foreach_{h}']:.0f} %; the step before "
                f"12-05 {100 * f[f'flop_fraction_before_{h}']:.0f} %; its matmuls alone "
                f"{100 * f[f'matmuls_alone_fraction_{h}']:.0f} %; fast ops on / off "
                f"{100 * f[f'flop_fraction_fast_ops_on_{h}']:.0f} / {100 * f[f'flop_fraction_fast_ops_off_{h}']:.0f} % "
                f"(the default here: {'on' if f['fast_ops_default'] else 'off'})"
            )
            if f"compile_s_{h}" in f:
                print(
                    f"    --compile: {f[f'compile_s_{h}']:.0f} s to compile, {f[f'compile_speedup_{h}']:.2f}× eager's "
                    f"steps/s, pays back after {f[f'compile_break_even_steps_{h}']:.0f} steps"
                )
    if "rollout" in parts:
        for env_name in ("ant", "half_cheetah"):
            r = bench_rollout(env_name, a.rounds)
            figures |= r
            print(
                f"rollout ({env_name}, 8 episodes × 200 steps, cpu-preset policy, "
                f"{r[f'physics_threads_{env_name}']} group(s) × {r[f'batch_threads_{env_name}']} MuJoCo threads): "
                f"{r[f'rollout_steps_per_s_{env_name}']:.0f} env "
                f"steps/s = {100 * r[f'rollout_fraction_{env_name}']:.0f} % of a one-thread mj_step loop "
                f"(serial physics {100 * r[f'rollout_fraction_serial_{env_name}']:.0f} %, 2 threads pipelined "
                f"{100 * r[f'rollout_fraction_pipelined_{env_name}']:.0f} %, one batch call on 2 threads "
                f"{100 * r[f'rollout_fraction_batch2_{env_name}']:.0f} %, acting through TorchActor "
                f"{100 * r[f'rollout_fraction_torch_{env_name}']:.0f} %; goal ≥ 90 %)"
            )
            print(
                f"  µs per step of the 8 envs: rollout {r[f'rollout_step_us_{env_name}']:.0f} = policy "
                f"{r[f'policy_us_{env_name}']:.0f} + physics {r[f'physics_us_{env_name}']:.0f} + the loop's rest; "
                f"the raw loop {r[f'raw_us_{env_name}']:.0f}"
            )
    if "sampling" in parts:
        s = bench_sampling(a.rounds)
        figures |= s
        print(f"device data path on the CPU: {s['device_sampling_ratio']:.2f}× the host path's time (goal ≤ 1)")
    if "checkpoint" in parts:
        c = bench_checkpoint()
        figures |= c
        print(
            f"periodic checkpoint (ant, cpu preset): {c['checkpoint_s']:.2f} s, {c['checkpoint_mb']:.1f} MB written "
            f"(goal < 1 s, < 50 MB; the whole replay is {c['replay_mb']:.0f} MB)"
        )
    if "kernels" in parts:
        k = bench_kernels()
        figures |= k
        for h in (256, 1024):
            print(
                f"kernels, 256 × {h}, forward + backward: tanh {k[f'tanh_us_{h}']:.0f} µs vs 2σ(2x) − 1 "
                f"{k[f'fast_tanh_us_{h}']:.0f} µs ({k[f'tanh_speedup_{h}']:.1f}×); one-output twin-Q layer by bmm "
                f"{k[f'one_output_bmm_us_{h}']:.0f} µs vs multiply-sum {k[f'one_output_fast_us_{h}']:.0f} µs "
                f"({k[f'one_output_speedup_{h}']:.1f}×)"
            )
        print(
            f"  --fast-ops by default on this host: {'on' if k['fast_ops_default'] else 'off'} (trainer/fast_ops.py; "
            f"its measurement took {k['fast_ops_measure_s']:.2f} s)"
        )
    if "aged" in parts:
        g = bench_aged(a.aged_epochs, max(a.rounds, 8))
        figures |= g
        print(
            f"a trained agent's update (point, cpu preset, {g['aged_epochs']} epochs, "
            f"{g['aged_denormals']} denormal values in its state): {g['aged_update_s_kept']:.3f} s per epoch, "
            f"{g['aged_update_s_flushed']:.3f} s flushing them ({g['flush_denormal_speedup']:.2f}×; "
            f"{g['aged_denormals_after']} left after)"
        )
    if "whole" in parts:
        w = bench_whole_run(a.whole_epochs)
        figures |= w
        print(
            f"a whole point cpu run of {w['whole_run_epochs']} epochs: {w['whole_run_s_kept']:.1f} s, "
            f"{w['whole_run_s_flushed']:.1f} s flushing denormals ({w['whole_run_speedup']:.2f}×)"
        )
    name = "update" if a.only is None else "-".join(["update", *parts])  # a partial run keeps the full file
    record(name, figures, {"env": a.env, "threads": torch.get_num_threads(), "device": str(dev)})


if __name__ == "__main__":
    main()
