"""make bench-encoders: one CNN shared by φ, Q and π against one CNN per network (the reference).

1. Speed: gradient steps/s of the full pixel update (φ, λ, SAC) for each, interleaved rounds on
   the same batches; the ratio is the figure (absolute numbers depend on the machine's load).
2. Learning on identical data: both start from the same seed and take the same K gradient steps
   on the same batches of random-action Quadruped frames (short episodes from many random
   initial orientations). Then a ridge probe asks how well the features π and Q read predict
   the torso's height and uprightness on held-out episodes — state that π must see to act and
   Q to judge, and large enough in a 64×64 frame for a linear probe (joint angles are not: R² ≈ 0
   even for trained features at this scale) — with untrained features as the baseline. Equal
   R² and finite losses mean the shared CNN loses nothing the update teaches in K steps; it
   cannot say how either fares over a 5000-epoch run.

    python benchmarks/bench_encoders.py --steps 150 --batch 32      # CPU, ≈ 15 min on 2 busy cores
    python benchmarks/bench_encoders.py --steps 2000 --batch 256     # a GPU

JSON (runs/bench/encoders.json): per kind (separate, shared) steps_per_s, train_s, final_losses,
probe_r2_untrained, probe_r2_policy, probe_r2_qf; and shared_over_separate_speed. Settings:
steps, batch, episodes, hidden, threads, device (the CPU and GPU commands above differ in them).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch
from gpu_sync import settled
from record import record

from trainer.config import make_config
from trainer.encoders import deterministic_convolutions
from trainer.envs import VectorEnv
from trainer.metra import Metra, TorchBatch
from trainer.skills import SkillPrior

ENV = "quadruped"


def collect(episodes: int, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random-action episodes: frames (n, T+1, 9, 64, 64) uint8, actions (n, T, 12), probe targets
    (n, T+1, 2): torso height and uprightness (the body z-axis' vertical component)."""
    env = VectorEnv(ENV, episodes, episode_steps=steps)
    rng = np.random.default_rng(seed)
    b = env.reset(list(range(seed, seed + episodes)))
    frames, poses, actions = [b.obs.copy()], [body_state(b.qpos)], []
    for _ in range(steps):
        a = rng.uniform(-1, 1, (episodes, env.action_dim)).astype(np.float32)
        b = env.step(a)
        frames.append(b.obs.copy())
        poses.append(body_state(b.qpos))
        actions.append(a)
    return np.stack(frames, 1), np.stack(actions, 1), np.stack(poses, 1)


def body_state(qpos: np.ndarray) -> np.ndarray:
    w, x, y, z = qpos[:, 3:7].T
    upright = 1 - 2 * (x * x + y * y) / (w * w + x * x + y * y + z * z)
    return np.stack([qpos[:, 2], upright], axis=1)


def batches(
    frames: np.ndarray, actions: np.ndarray, prior: SkillPrior, n: int, size: int, dev: torch.device
) -> list[TorchBatch]:
    rng = np.random.default_rng(0)
    skills = prior.sample(len(frames), rng)  # one skill per episode, as in a rollout
    out = []
    for _ in range(n):
        i, t = rng.integers(0, len(frames), size), rng.integers(0, actions.shape[1], size)
        z = torch.as_tensor(skills[i], device=dev)

        def img(x: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(x, dtype=torch.float32, device=dev) / 255.0

        out.append(
            TorchBatch(img(frames[i, t]), img(frames[i, t + 1]), torch.as_tensor(actions[i, t], device=dev), z, z)
        )
    return out


@torch.no_grad()
def features(encoder: torch.nn.Module, frames: np.ndarray, dev: torch.device) -> np.ndarray:
    flat = frames.reshape(-1, *frames.shape[2:])
    out = [
        encoder(torch.as_tensor(flat[i : i + 256], dtype=torch.float32, device=dev) / 255.0)
        for i in range(0, len(flat), 256)
    ]
    f = torch.cat([o if o.dim() == 2 else o[0] for o in out])  # twin critics: the first one's CNN
    return f.cpu().numpy().astype(np.float64)


def ridge_r2(
    train_x: np.ndarray, train_y: np.ndarray, test_x: np.ndarray, test_y: np.ndarray, alpha: float = 1.0
) -> float:
    """Held-out R² (averaged over targets) of a ridge regression on standardised features."""
    mu, sd = train_x.mean(0), train_x.std(0) + 1e-6
    a, b = (train_x - mu) / sd, (test_x - mu) / sd
    ym = train_y.mean(0)
    w = np.linalg.solve(a.T @ a + alpha * len(a) * np.eye(a.shape[1]), a.T @ (train_y - ym))
    pred = b @ w + ym
    return float(np.mean(1 - ((test_y - pred) ** 2).sum(0) / ((test_y - test_y.mean(0)) ** 2).sum(0)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=150, help="gradient steps per encoder kind")
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--episodes", type=int, default=40, help="50-step training episodes (plus 40%% more held out)")
    p.add_argument("--hidden", type=int, default=1024)
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    deterministic_convolutions()  # as a run's convolutions on a GPU
    frames, actions, pose = collect(a.episodes, 50, seed=0)
    held_frames, _, held_pose = collect(max(2, 2 * a.episodes // 5), 50, seed=1000)
    prior = SkillPrior(make_config("paper", ENV).skill_dim, False)
    data = batches(frames, actions, prior, a.steps, a.batch, dev)
    probe_train, probe_test = frames[:, ::2], held_frames[:, ::2]
    y_train, y_test = pose[:, ::2].reshape(-1, pose.shape[-1]), held_pose[:, ::2].reshape(-1, pose.shape[-1])

    agents, report = {}, {}
    for kind in ("separate", "shared"):
        torch.manual_seed(0)
        cfg = make_config("paper", ENV, encoder=kind, hidden=a.hidden, batch_size=a.batch)
        agents[kind] = Metra((9, 64, 64), actions.shape[-1], prior, cfg, dev)
    for kind, agent in agents.items():
        report[kind] = {
            "probe_r2_untrained": ridge_r2(
                features(agent.policy.encoder, probe_train, dev),
                y_train,
                features(agent.policy.encoder, probe_test, dev),
                y_test,
            )
        }
    for kind, agent in agents.items():  # learning: the same K batches for both
        start, losses = time.perf_counter(), []
        for b in data:
            info = agent.update(b, None)
            losses.append({k: float(info[k]) for k in ("phi_loss", "qf_loss", "policy_loss")})
        report[kind]["train_s"] = time.perf_counter() - start
        report[kind]["final_losses"] = {k: float(np.mean([x[k] for x in losses[-10:]])) for k in losses[-1]}
        for net in ("policy", "qf"):
            enc = getattr(agent, net).encoder
            report[kind][f"probe_r2_{net}"] = ridge_r2(
                features(enc, probe_train, dev), y_train, features(enc, probe_test, dev), y_test
            )
    speed = {kind: {"steps_per_s": []} for kind in agents}
    for _ in range(3):  # interleaved rounds: both see the same machine load
        for kind, agent in agents.items():
            settled(dev)  # a GPU's queued kernels done: timed, not only queued
            start = time.perf_counter()
            for b in data[:5]:
                agent.update(b, None)
            settled(dev)
            speed[kind]["steps_per_s"].append(5 / (time.perf_counter() - start))
    for kind in agents:
        report[kind]["steps_per_s"] = float(np.median(speed[kind]["steps_per_s"]))
    sep, sh = report["separate"], report["shared"]
    print(
        f"device {dev}, {torch.get_num_threads()} threads, batch {a.batch}, hidden {a.hidden}, {a.steps} steps, "
        f"{len(y_train)} probe states, {len(y_test)} held out"
    )
    for kind, r in report.items():
        print(
            f"{kind:9s} {r['steps_per_s']:6.2f} grad steps/s   height+upright R² from π's features "
            f"{r['probe_r2_untrained']:.3f} → {r['probe_r2_policy']:.3f}, from Q's {r['probe_r2_qf']:.3f}   "
            f"losses {r['final_losses']}"
        )
    print(f"shared / separate speed: {sh['steps_per_s'] / sep['steps_per_s']:.2f}×")
    print(json.dumps(report))
    settings = {"steps": a.steps, "batch": a.batch, "episodes": a.episodes, "hidden": a.hidden}
    settings |= {"threads": torch.get_num_threads(), "device": str(dev)}  # the figures depend on every one
    record("encoders", {**report, "shared_over_separate_speed": sh["steps_per_s"] / sep["steps_per_s"]}, settings)


if __name__ == "__main__":
    main()
