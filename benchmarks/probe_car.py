"""make probe-car: how the Safety-Gym-style car moves (docs/envs.md, the car's dynamics).

From the initial state of each seed (a random heading), one 200-step episode of open-loop actions:
full throttle on both wheels (the distance covered, the top speed over one control step and the
angle between the path and the initial heading) and opposite wheels (the spin rate over the second
half of the episode, once it is up to speed). The straight run is repeated with MuJoCo's default
pyramidal friction cones, which the car does not use: with them the path veers by an amount that
depends on the heading. No torch, no training: seconds.

    python benchmarks/probe_car.py --seeds 8

JSON (runs/bench/car.json): seeds, distance_m (mean over seeds), top_speed_m_s (max), spin_rad_s
(mean), veer_rad (max over seeds, elliptic cones: the env's) and veer_pyramidal_rad (max, pyramidal).
"""

from __future__ import annotations

import argparse
import math

import mujoco
import numpy as np
from record import record

from trainer.envs import make_env
from trainer.envs.car import CarEnv


def drive(env: CarEnv, seed: int, action: np.ndarray) -> tuple[np.ndarray, list[float]]:
    """One episode of a fixed action: the x-y path (steps + 1, 2) and the yaw at every step."""
    env.reset(seed=seed)
    path, yaws = [env.data.qpos[:2].copy()], [env.yaw()]
    for _ in range(env.episode_steps):
        env.step(action)
        path.append(env.data.qpos[:2].copy())
        yaws.append(env.yaw())
    return np.array(path), yaws


def veer(path: np.ndarray, start_yaw: float) -> float:
    """|angle| between the straight run's displacement and the heading it started with."""
    dx, dy = path[-1] - path[0]
    return abs(math.remainder(math.atan2(dy, dx) - start_yaw, 2 * math.pi))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=8, help="initial states (headings) of seeds 0 … N−1")
    args = p.parse_args()
    if args.seeds < 1:
        p.error(f"--seeds must be ≥ 1, got {args.seeds}")
    env = make_env("car", seed=0)
    assert isinstance(env, CarEnv)
    control_dt = env.model.opt.timestep * env.frame_skip
    ahead, spin = np.ones(2), np.array([1.0, -1.0])
    distances, speeds, spins, veers, veers_pyramidal = [], [], [], [], []
    for seed in range(args.seeds):
        path, yaws = drive(env, seed, ahead)
        distances.append(float(np.linalg.norm(path[-1] - path[0])))
        speeds.append(float(np.linalg.norm(np.diff(path, axis=0), axis=1).max() / control_dt))
        veers.append(veer(path, yaws[0]))
        _, turning = drive(env, seed, spin)
        half = len(turning) // 2
        turned = np.unwrap(np.array(turning[half:]))
        spins.append(float(abs(turned[-1] - turned[0]) / ((len(turned) - 1) * control_dt)))
        env.model.opt.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
        path, yaws = drive(env, seed, ahead)
        veers_pyramidal.append(veer(path, yaws[0]))
        env.model.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        print(
            f"seed {seed}: heading {yaws[0]:+.2f} rad, {distances[-1]:.2f} m, top {speeds[-1]:.2f} m/s, "
            f"spin {spins[-1]:.2f} rad/s, veer {veers[-1]:.3f} rad (pyramidal cones: {veers_pyramidal[-1]:.3f})",
            flush=True,
        )
    env.close()
    figures = {
        "seeds": args.seeds,
        "distance_m": round(float(np.mean(distances)), 2),
        "top_speed_m_s": round(max(speeds), 2),
        "spin_rad_s": round(float(np.mean(spins)), 2),
        "veer_rad": round(max(veers), 3),
        "veer_pyramidal_rad": round(max(veers_pyramidal), 3),
    }
    print(", ".join(f"{k} {v}" for k, v in figures.items()))
    record("car", figures)


if __name__ == "__main__":
    main()
