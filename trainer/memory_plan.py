"""Whether a run's sizes fit this machine's memory, checked before the run allocates them.

Linux lends memory lazily: numpy's `np.zeros` for a replay of 20 GB, or a MuJoCo model per env for
100 000 evaluation envs, succeed at once and the pages are taken as they are touched, until the
kernel kills the process (exit 137, no word) hours or minutes later. So the trainer compares what
its sizes will touch with what the machine has free now, and refuses, naming the sizes, where even
a lower bound does not fit: a run that could fit is never refused.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MEMINFO = Path("/proc/meminfo")
GIB = 2**30
ENVS_MEASURED = 4  # envs made before the rest are projected from their cost


class NotEnoughMemory(MemoryError):
    """`needed` bytes (a lower bound) against `available`; `what` names the allocation."""

    def __init__(self, what: str, needed: int, available: int) -> None:
        self.what, self.needed, self.available = what, needed, available
        super().__init__(f"{what}: at least {needed / GIB:.1f} GiB, {available / GIB:.1f} GiB free")


def available_bytes(meminfo: Path = MEMINFO) -> int | None:
    """Memory a process can still take: MemAvailable + SwapFree (None where there is no
    /proc/meminfo, e.g. macOS: then nothing is checked)."""
    try:
        fields = dict(line.split(":", 1) for line in meminfo.read_text().splitlines() if ":" in line)
        return (int(fields["MemAvailable"].split()[0]) + int(fields.get("SwapFree", "0 kB").split()[0])) * 1024
    except (OSError, KeyError, ValueError):
        return None


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
