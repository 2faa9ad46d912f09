"""The trainer's memory plan (trainer/memory_plan.py): its figures are lower bounds of what the run
takes, read from the machine as Linux states them."""

from pathlib import Path

import numpy as np
import pytest

from trainer.config import PRESETS, make_config
from trainer.envs.registry import ENV_NAMES, make_env
from trainer.memory_ledger import LEDGER_ENV, check_beside_others
from trainer.memory_plan import (
    GIB,
    NotEnoughMemory,
    available_bytes,
    container_free_bytes,
    replay_fill_bytes,
    run_floor_bytes,
)
from trainer.replay import TrajectoryReplay


@pytest.mark.parametrize(("obs_shape", "dtype"), [((29,), np.float32), ((9, 64, 64), np.uint8)])  # Ant; pixels
def test_the_replay_s_figure_is_a_close_lower_bound_of_its_arrays(obs_shape, dtype) -> None:
    steps, trajectories, action, nq, nv, skill = 200, 10, 8, 15, 14, 2
    replay = TrajectoryReplay(steps * trajectories, steps, obs_shape, action, skill, nq, nv, dtype)
    arrays = sum(a.nbytes for a in vars(replay).values() if isinstance(a, np.ndarray))
    planned = replay_fill_bytes(trajectories, steps, obs_shape, np.dtype(dtype), action, nq, nv)
    assert 0.99 * arrays <= planned <= arrays  # only the per-trajectory skill, epoch and flag left out


def test_free_memory_is_what_is_available_and_the_free_swap(tmp_path: Path) -> None:
    meminfo, no_cgroup = tmp_path / "meminfo", tmp_path / "no-cgroup"
    meminfo.write_text("MemTotal: 24000000 kB\nMemFree: 100 kB\nMemAvailable: 2097152 kB\nSwapFree: 1048576 kB\n")
    assert available_bytes(meminfo, no_cgroup, no_cgroup) == 3 * GIB
    meminfo.write_text("MemTotal: 24000000 kB\n")  # a kernel before 3.14: no MemAvailable, nothing checked
    assert available_bytes(meminfo, no_cgroup, no_cgroup) is None
    assert available_bytes(tmp_path / "absent", no_cgroup, no_cgroup) is None


def limit(folder: Path, files: tuple[str, str], limit: int | str, usage: int, stat: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / files[0]).write_text(f"{limit}\n")
    (folder / files[1]).write_text(f"{usage}\n")
    (folder / "memory.stat").write_text(stat)


V2, V1 = ("memory.max", "memory.current"), ("memory.limit_in_bytes", "memory.usage_in_bytes")


def test_a_container_s_limit_leaves_less_than_the_host_shows(tmp_path: Path) -> None:
    """/proc/meminfo shows the host: a container limited to 2 GiB that holds 1.5 GiB, 0.25 GiB of it
    page cache the kernel can drop, has 0.75 GiB left, however much the host has free."""
    meminfo, member = tmp_path / "meminfo", tmp_path / "cgroup-of-self"
    meminfo.write_text("MemAvailable: 20971520 kB\n")  # the host: 20 GiB
    member.write_text("0::/\n")  # cgroup v2, in the container's own namespace
    v2 = tmp_path / "v2"
    limit(v2, V2, 2 * GIB, GIB + GIB // 2, f"anon 1\ninactive_file {GIB // 8}\nactive_file {GIB // 8}\n")
    assert available_bytes(meminfo, v2, member) == container_free_bytes(v2, member) == GIB * 3 // 4
    limit(v2, V2, "max", GIB, "")  # no limit: the host's figure
    assert container_free_bytes(v2, member) is None and available_bytes(meminfo, v2, member) == 20 * GIB


def test_the_swap_a_container_may_still_use_counts_as_free(tmp_path: Path) -> None:
    """Docker's default --memory-swap lets a container swap as much again: a run that fits in memory
    and swap is not refused (at most the host's free swap counts)."""
    meminfo, member, v2 = tmp_path / "meminfo", tmp_path / "cgroup-of-self", tmp_path / "v2"
    meminfo.write_text("MemAvailable: 20971520 kB\nSwapFree: 1048576 kB\n")  # 20 GiB, 1 GiB of swap free
    member.write_text("0::/\n")
    limit(v2, V2, 2 * GIB, GIB, "")
    (v2 / "memory.swap.max").write_text(f"{2 * GIB}\n")
    (v2 / "memory.swap.current").write_text(f"{GIB + GIB // 2}\n")
    assert available_bytes(meminfo, v2, member) == GIB + GIB // 2  # 1 GiB of memory, 0.5 of swap left
    (v2 / "memory.swap.max").write_text("max\n")  # as much as the host has
    assert available_bytes(meminfo, v2, member) == 2 * GIB
    v1 = tmp_path / "v1"  # v1 with swap accounting: memory and swap under one more limit
    member.write_text("4:memory:/\n")
    limit(v1 / "memory", V1, 2 * GIB, GIB, "")
    (v1 / "memory" / "memory.memsw.limit_in_bytes").write_text(f"{3 * GIB}\n")
    (v1 / "memory" / "memory.memsw.usage_in_bytes").write_text(f"{2 * GIB + GIB // 4}\n")
    assert available_bytes(meminfo, v1, member) == GIB * 3 // 4  # memory and swap: 0.75 GiB left in all


def test_a_limit_on_a_cgroup_above_this_process_s_counts_too(tmp_path: Path) -> None:
    """cgroup v1 without a namespace (a pod's limit on its parent cgroup): the process's own cgroup
    is unlimited (v1 writes that as 2^63 rounded to a page), its parent leaves 1.5 GiB."""
    member, v1 = tmp_path / "cgroup-of-self", tmp_path / "v1"
    member.write_text("12:pids:/pod/ctr\n4:memory,hugetlb:/pod/ctr\n0::/\n")
    limit(v1 / "memory" / "pod" / "ctr", V1, 9223372036854771712, GIB, "total_inactive_file 0\n")
    limit(v1 / "memory" / "pod", V1, 2 * GIB, GIB, f"cache 5\ntotal_inactive_file {GIB // 2}\n")
    assert container_free_bytes(v1, member) == GIB * 3 // 2


def test_a_size_beyond_free_memory_is_refused_with_both_figures(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv(LEDGER_ENV, str(tmp_path / "ledger"))  # no other run promised anything
    check_beside_others("the replay", 2 * GIB, available=3 * GIB)  # fits: nothing said
    with pytest.raises(NotEnoughMemory, match=r"^the replay: at least 4\.0 GiB, 3\.0 GiB free$") as caught:
        check_beside_others("the replay", 4 * GIB, available=3 * GIB)
    assert isinstance(caught.value, MemoryError)  # `collie train` names the sizes given for any MemoryError


def test_every_preset_needs_less_than_16_gib_free() -> None:
    """The check refuses only sizes beyond the machine: each env's presets need less than 16 GiB
    free by its count (the pixel `paper` runs' replay of uint8 frames the most)."""
    for env_name in ENV_NAMES:
        env = make_env(env_name)
        for preset in PRESETS:
            needed = run_floor_bytes(make_config(preset, env_name), env)
            assert 0 < needed < 16 * GIB, (env_name, preset, needed / GIB)
