"""Whether a run's sizes fit this machine's memory, checked before the run allocates them.

Linux lends memory lazily: numpy's `np.zeros` for a replay of 20 GB, or a MuJoCo model per env for
100 000 evaluation envs, succeed at once and the pages are taken as they are touched, until the
kernel kills the process (exit 137, no word) hours or minutes later. So the trainer compares what
its sizes will touch with what the machine has free now, and refuses, naming the sizes, where even
a lower bound does not fit: a run that could fit is never refused.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from trainer.replay import trajectories_held

if TYPE_CHECKING:
    from trainer.config import Config

MEMINFO = Path("/proc/meminfo")
CGROUP = Path("/sys/fs/cgroup")  # this process's memory cgroup, as a container mounts it
MEMBERSHIP = Path("/proc/self/cgroup")  # which cgroups this process is in
UNLIMITED = 2**60  # cgroup v1 writes "no limit" as a page-rounded 2^63
GIB = 2**30
ENVS_MEASURED = 16  # envs made (≈ 10 ms each) before the rest are projected from their cost
PROJECTED_SHARE = 0.85  # of that cost: the first envs take ≈ 10 % more each than later ones (point, here)


class NotEnoughMemory(MemoryError):
    """`needed` bytes (a lower bound) against `available`, of which `held` is promised to the runs
    `holders` on this machine (trainer/memory_ledger.py); `what` names the allocation."""

    def __init__(self, what: str, needed: int, available: int, held: int = 0, holders: tuple[int, ...] = ()) -> None:
        self.what, self.needed, self.available, self.held, self.holders = what, needed, available, held, holders
        said = f"{what}: at least {needed / GIB:.1f} GiB, {available / GIB:.1f} GiB free"
        if self.fits_alone:  # else what others hold is no matter: it would not fit alone either
            runs = ("pid " if len(holders) == 1 else "pids ") + ", ".join(str(pid) for pid in holders)
            said += f", {size(min(held, available))} of it promised to running runs ({runs})"
        super().__init__(said)

    @property
    def fits_alone(self) -> bool:
        """Refused only for what running runs were promised: it fits once they end."""
        return self.held > 0 and self.needed <= self.available


def refusal_status(exc: BaseException) -> int:
    """A refused start's exit status: EX_TEMPFAIL (75) where only memory running runs were promised
    is why (a sweep, `collie up` start it again once they have ended), else 2."""
    return os.EX_TEMPFAIL if isinstance(exc, NotEnoughMemory) and exc.fits_alone else 2


def size(n: int) -> str:
    """Bytes as people read them here: GiB to a tenth, MiB below a tenth of a GiB."""
    if n >= GIB / 10:
        return f"{n / GIB:.1f} GiB"
    return f"{n / 2**20:.0f} MiB" if n >= 2**20 else "under 1 MiB"


def available_bytes(meminfo: Path = MEMINFO, cgroup: Path = CGROUP, membership: Path = MEMBERSHIP) -> int | None:
    """Memory a process can still take: MemAvailable + SwapFree, or less where its container's
    limit leaves less (None where there is no /proc/meminfo, e.g. macOS: then nothing is checked)."""
    try:
        fields = dict(line.split(":", 1) for line in meminfo.read_text().splitlines() if ":" in line)
        swap = int(fields.get("SwapFree", "0 kB").split()[0]) * 1024
        free = int(fields["MemAvailable"].split()[0]) * 1024 + swap
    except (OSError, KeyError, ValueError):
        return None
    limited = container_free_bytes(cgroup, membership, swap)
    return free if limited is None else min(free, limited)


def container_free_bytes(cgroup: Path = CGROUP, membership: Path = MEMBERSHIP, swap_free: int = 0) -> int | None:
    """What the memory cgroups' limits leave this process (a container's `--memory`, a pod's
    limit), whose excess the kernel kills as it would at the machine's end: the least, over its
    cgroup and those above it, of limit − (usage − page cache), plus the swap the cgroup may still
    use (at most `swap_free`, the host's). cgroup v2 and v1; None without a limit. (/proc/meminfo
    shows the host's memory.)"""
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
    left = [
        *(v2_free(cgroup / p, swap_free) for p in up_from(where["v2"])),
        *(v1_free(cgroup / "memory" / p, swap_free) for p in up_from(where["v1"])),
    ]
    limited = [free for free in left if free is not None]
    return min(limited) if limited else None


def up_from(path: str) -> list[str]:
    """A cgroup's path and its ancestors', relative to the mount: "/a/b" → ["a/b", "a", ""]."""
    parts = [p for p in path.split("/") if p]
    return ["/".join(parts[:n]) for n in range(len(parts), -1, -1)]


def v2_free(folder: Path, swap_free: int) -> int | None:
    """memory.max − memory.current + page cache, and memory.swap.max − memory.swap.current."""
    limit, usage = number(folder / "memory.max"), number(folder / "memory.current")
    if limit is None or usage is None:  # absent, or "max": no limit here
        return None
    swap_limit, swap_used = number(folder / "memory.swap.max"), number(folder / "memory.swap.current")
    swap = swap_free if swap_limit is None or swap_used is None else min(swap_free, max(0, swap_limit - swap_used))
    return max(0, limit - usage + page_cache(folder, "")) + swap


def v1_free(folder: Path, swap_free: int) -> int | None:
    """As v2, from memory.limit_in_bytes; memory.memsw.* (memory and swap together) where the
    kernel accounts swap to cgroups."""
    limit, usage = number(folder / "memory.limit_in_bytes"), number(folder / "memory.usage_in_bytes")
    if limit is None or usage is None:
        return None
    both, both_used = number(folder / "memory.memsw.limit_in_bytes"), number(folder / "memory.memsw.usage_in_bytes")
    cache = page_cache(folder, "total_")
    if both is not None and both_used is not None:  # swap within the same limit
        return max(0, min(limit - usage + cache + swap_free, both - both_used + cache))
    return max(0, limit - usage + cache) + swap_free


def number(path: Path) -> int | None:
    """A cgroup file's number; None if absent, unreadable, or no limit ("max", v1's ~2^63)."""
    try:
        value = int(path.read_text())
    except (OSError, ValueError):
        return None
    return value if value < UNLIMITED else None


def page_cache(folder: Path, prefix: str) -> int:
    """The file pages memory.stat counts in the cgroup's usage, which the kernel drops before it
    kills (as MemAvailable counts them)."""
    try:
        stat = dict(line.split() for line in (folder / "memory.stat").read_text().splitlines())
        return int(stat.get(f"{prefix}inactive_file", 0)) + int(stat.get(f"{prefix}active_file", 0))
    except (OSError, ValueError):
        return 0


def resident_bytes() -> int | None:
    """This process's resident set (None without /proc)."""
    try:
        return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, IndexError, ValueError):
        return None


def replay_fill_bytes(
    trajectories: int, steps: int, obs_shape: tuple[int, ...], obs_dtype: np.dtype, action_dim: int, nq: int, nv: int
) -> int:
    """What a replay of `trajectories` (as many as the run will store) touches: its arrays'
    bytes per trajectory (trainer/replay.py), times the trajectories."""
    states = steps + 1
    obs = states * int(np.prod(obs_shape)) * np.dtype(obs_dtype).itemsize
    floats = steps * action_dim + states * (2 + 1 + nq + nv)  # actions; xy, pitch, qpos, qvel per state
    return trajectories * (obs + 4 * floats)


def learner_floor_bytes(batch_size: int, hidden: int, layers: int, obs_shape: tuple[int, ...]) -> int:
    """A lower bound on the learner on the CPU: the hidden-to-hidden weights of the policy, two
    critics and φ with Adam's two moments each, and for one gradient step the batch's s and s′ as
    float32 and one activation of each layer of the policy and two critics (it holds far more)."""
    weights = 4 * (layers - 1) * hidden * hidden * 4 * 3
    return weights + batch_size * (2 * 4 * int(np.prod(obs_shape)) + 3 * layers * 4 * hidden)


class EnvShapes(Protocol):  # a SkillEnv's or a VectorEnv's
    obs_shape: tuple[int, ...]
    obs_dtype: np.dtype
    action_dim: int
    nq: int
    nv: int


def run_floor_bytes(cfg: Config, env: EnvShapes, on_cpu: bool = True) -> int:
    """A lower bound on the host memory a run of `cfg` on `env` touches besides its envs: the replay
    as far as the run fills it (its capacity, or every trajectory of its epochs if fewer) and, on
    the CPU, the learner (on a GPU, its networks, batch and activations are in the GPU's memory)."""
    stored = min(trajectories_held(cfg.replay_capacity, cfg.episode_steps), cfg.epochs * cfg.episodes_per_epoch)
    replay = replay_fill_bytes(stored, cfg.episode_steps, env.obs_shape, env.obs_dtype, env.action_dim, env.nq, env.nv)
    return replay + (learner_floor_bytes(cfg.batch_size, cfg.hidden, cfg.layers, env.obs_shape) if on_cpu else 0)
