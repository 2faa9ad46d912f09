"""Whether a run's sizes fit this machine's memory, checked before the run allocates them.

Linux lends memory lazily: numpy's `np.zeros` for a replay of 20 GB, or a MuJoCo model per env for
100 000 evaluation envs, succeed at once and the pages are taken as they are touched, until the
kernel kills the process (exit 137, no word) hours or minutes later. So the trainer compares what
its sizes will touch with what the machine has free now, and refuses, naming the sizes, where even
a lower bound does not fit: a run that could fit is never refused.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from trainer.config import Config

MEMINFO = Path("/proc/meminfo")
CGROUP = Path("/sys/fs/cgroup")  # this process's memory cgroup, as a container mounts it
MEMBERSHIP = Path("/proc/self/cgroup")  # which cgroups this process is in
UNLIMITED = 2**60  # cgroup v1 writes "no limit" as a page-rounded 2^63
GIB = 2**30
ENVS_MEASURED = 4  # envs made before the rest are projected from their cost


class NotEnoughMemory(MemoryError):
    """`needed` bytes (a lower bound) against `available`; `what` names the allocation."""

    def __init__(self, what: str, needed: int, available: int) -> None:
        self.what, self.needed, self.available = what, needed, available
        super().__init__(f"{what}: at least {needed / GIB:.1f} GiB, {available / GIB:.1f} GiB free")


def available_bytes(meminfo: Path = MEMINFO, cgroup: Path = CGROUP, membership: Path = MEMBERSHIP) -> int | None:
    """Memory a process can still take: MemAvailable + SwapFree, or less where its container's
    limit leaves less (None where there is no /proc/meminfo, e.g. macOS: then nothing is checked)."""
    try:
        fields = dict(line.split(":", 1) for line in meminfo.read_text().splitlines() if ":" in line)
        free = (int(fields["MemAvailable"].split()[0]) + int(fields.get("SwapFree", "0 kB").split()[0])) * 1024
    except (OSError, KeyError, ValueError):
        return None
    limited = container_free_bytes(cgroup, membership)
    return free if limited is None else min(free, limited)


def container_free_bytes(cgroup: Path = CGROUP, membership: Path = MEMBERSHIP) -> int | None:
    """What the memory cgroups' limits leave this process (a container's `--memory`, a pod's
    limit), whose excess the kernel kills as it would at the machine's end: the least, over its
    cgroup and those above it, of limit − (usage − reclaimable page cache). cgroup v2 and v1; None
    without a limit. (/proc/meminfo shows the host's memory.)"""
    try:
        lines = [line.split(":", 2) for line in membership.read_text().splitlines() if line.count(":") >= 2]
    except OSError:
        lines = []
    where = {"v2": "/", "v1": "/"}  # in a container with its own cgroup namespace: its root
    for hierarchy, controllers, path in lines:
        if hierarchy == "0" and not controllers:
            where["v2"] = path
        elif "memory" in controllers.split(","):
            where["v1"] = path
    levels = [  # (folder, limit file, usage file, reclaimable key in memory.stat)
        *((cgroup / p, "memory.max", "memory.current", "inactive_file") for p in up_from(where["v2"])),
        *(
            (cgroup / "memory" / p, "memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file")
            for p in up_from(where["v1"])
        ),
    ]
    left = [free for level in levels if (free := cgroup_free(*level)) is not None]
    return min(left) if left else None


def up_from(path: str) -> list[str]:
    """A cgroup's path and its ancestors', relative to the mount: "/a/b" → ["a/b", "a", ""]."""
    parts = [p for p in path.split("/") if p]
    return ["/".join(parts[:n]) for n in range(len(parts), -1, -1)]


def cgroup_free(folder: Path, limit_file: str, usage_file: str, reclaimable: str) -> int | None:
    try:
        limit, usage = int((folder / limit_file).read_text()), int((folder / usage_file).read_text())
    except (OSError, ValueError):  # absent, or v2's "max": no limit here
        return None
    if limit >= UNLIMITED:
        return None
    try:
        cache = int(dict(line.split() for line in (folder / "memory.stat").read_text().splitlines())[reclaimable])
    except (OSError, ValueError, KeyError):
        cache = 0
    return max(0, limit - usage + cache)


def resident_bytes() -> int | None:
    """This process's resident set (None without /proc)."""
    try:
        return int(Path("/proc/self/statm").read_text().split()[1]) * 4096
    except (OSError, IndexError, ValueError):
        return None


def check(what: str, needed: int, available: int | None = None) -> None:
    """Raise NotEnoughMemory if `needed` bytes exceed what is free (`available`, read now if None)."""
    free = available_bytes() if available is None else available
    if free is not None and needed > free:
        raise NotEnoughMemory(what, needed, free)


def replay_fill_bytes(
    trajectories: int, steps: int, obs_shape: tuple[int, ...], obs_dtype: np.dtype, action_dim: int, nq: int, nv: int
) -> int:
    """What a replay of `trajectories` (as many as the run will store) touches: its arrays'
    bytes per trajectory (trainer/replay.py), times the trajectories."""
    states = steps + 1
    obs = states * int(np.prod(obs_shape)) * np.dtype(obs_dtype).itemsize
    floats = steps * action_dim + states * (2 + 1 + nq + nv)  # actions; xy, pitch, qpos, qvel per state
    return trajectories * (obs + 4 * floats)


def update_floor_bytes(batch_size: int, hidden: int, obs_shape: tuple[int, ...]) -> int:
    """A lower bound on one gradient step: the batch's s and s′ as float32, and one hidden
    activation of each layer (two) for the policy and two critics (the step holds far more)."""
    return batch_size * (2 * 4 * int(np.prod(obs_shape)) + 3 * 2 * 4 * hidden)


class EnvShapes(Protocol):  # a SkillEnv's or a VectorEnv's
    obs_shape: tuple[int, ...]
    obs_dtype: np.dtype
    action_dim: int
    nq: int
    nv: int


def run_floor_bytes(cfg: Config, env: EnvShapes) -> int:
    """A lower bound on what a run of `cfg` on `env` touches besides its envs: the replay as far as
    the run fills it (its capacity, or every trajectory of its epochs if fewer) and a gradient step."""
    stored = min(max(1, cfg.replay_capacity // cfg.episode_steps), cfg.epochs * cfg.episodes_per_epoch)
    shapes = (env.obs_shape, env.obs_dtype, env.action_dim, env.nq, env.nv)
    return replay_fill_bytes(stored, cfg.episode_steps, *shapes) + update_floor_bytes(
        cfg.batch_size, cfg.hidden, env.obs_shape
    )
