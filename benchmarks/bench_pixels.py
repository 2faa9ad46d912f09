"""make bench-pixels: agent steps per second of the pixel envs on ONE core (target ≥ 200/s).

An agent step = action repeat 2 of physics + one 64×64 render (shadows, reflections, skybox and
multisampling off; coarse tessellation; a 2 m floor grid). Mesa's renderer is pinned to one
thread (LP_NUM_THREADS=1) and so is the process (os.sched_setaffinity), so the figure is per
core. For context it also prints physics alone, rendering alone, and dm_control's own 64×64
render at its default settings (what one gets without these choices).
JSON (runs/bench/pixels.json): per env, agent_steps_per_s, physics_agent_steps_per_s, renders_per_s,
dm_control_default_renders_per_s.
"""

from __future__ import annotations

import os

os.environ.setdefault("LP_NUM_THREADS", "1")  # read when Mesa creates its first context
os.environ.setdefault("MUJOCO_GL", "egl")

import argparse
import json
import time

import mujoco
import numpy as np
from record import record

from trainer.envs import make_env, raw_step_rate

TARGET = 200.0


def rate(fn, steps: int) -> float:
    start = time.perf_counter()
    for _ in range(steps):
        fn()
    return steps / (time.perf_counter() - start)


def bench(name: str, steps: int) -> dict[str, float]:
    full = raw_step_rate(name, steps=steps)  # public step(): physics + render + frame stack, resets included
    env = make_env(name, seed=0)
    env.reset()
    rng = np.random.default_rng(0)

    def physics() -> None:
        env.data.ctrl[:] = rng.uniform(-1, 1, env.action_dim)
        mujoco.mj_step(env.model, env.data, nstep=env.frame_skip)

    physics_rate = rate(physics, steps)
    render_rate = rate(env.render, steps)
    env.physics.model.vis.quality.offsamples = 4  # dm_control's defaults, in its own context
    dmc_rate = rate(lambda: env.physics.render(64, 64, camera_id="pixels"), max(20, steps // 20))
    env.close()
    return {
        "agent_steps_per_s": full,
        "physics_agent_steps_per_s": physics_rate,
        "renders_per_s": render_rate,
        "dm_control_default_renders_per_s": dmc_rate,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", default=["quadruped", "humanoid"])
    p.add_argument("--steps", type=int, default=2000)
    a = p.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    print(f"MUJOCO_GL={os.environ['MUJOCO_GL']}, LP_NUM_THREADS={os.environ['LP_NUM_THREADS']}, one core")
    results = {}
    for name in a.envs:
        r = bench(name, a.steps)
        results[name] = r
        verdict = "ok" if r["agent_steps_per_s"] >= TARGET else "BELOW TARGET"
        print(
            f"{name:10s} {r['agent_steps_per_s']:7.0f} agent steps/s (step + render; target ≥ {TARGET:.0f}: "
            f"{verdict})   physics alone {r['physics_agent_steps_per_s']:6.0f}/s   render alone "
            f"{r['renders_per_s']:6.0f}/s   dm_control default render {r['dm_control_default_renders_per_s']:4.0f}/s"
        )
    print(json.dumps(results))
    record("pixels", results)


if __name__ == "__main__":
    main()
