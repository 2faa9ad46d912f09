"""The trainer's memory plan (trainer/memory_plan.py): its figures are lower bounds of what the run
takes, read from the machine as Linux states them."""

from pathlib import Path

import numpy as np
import pytest

from trainer.memory_plan import GIB, NotEnoughMemory, available_bytes, check, replay_fill_bytes
from trainer.replay import TrajectoryReplay


@pytest.mark.parametrize(("obs_shape", "dtype"), [((29,), np.float32), ((9, 64, 64), np.uint8)])  # Ant; pixels
def test_the_replay_s_figure_is_a_close_lower_bound_of_its_arrays(obs_shape, dtype) -> None:
    steps, trajectories, action, nq, nv, skill = 200, 10, 8, 15, 14, 2
    replay = TrajectoryReplay(steps * trajectories, steps, obs_shape, action, skill, nq, nv, dtype)
    arrays = sum(a.nbytes for a in vars(replay).values() if isinstance(a, np.ndarray))
    planned = replay_fill_bytes(trajectories, steps, obs_shape, np.dtype(dtype), action, nq, nv)
    assert 0.99 * arrays <= planned <= arrays  # only the per-trajectory skill, epoch and flag left out


def test_free_memory_is_what_is_available_and_the_free_swap(tmp_path: Path) -> None:
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal: 24000000 kB\nMemFree: 100 kB\nMemAvailable: 2097152 kB\nSwapFree: 1048576 kB\n")
    assert available_bytes(meminfo) == 3 * GIB
    meminfo.write_text("MemTotal: 24000000 kB\n")  # a kernel before 3.14: no MemAvailable, nothing checked
    assert available_bytes(meminfo) is None and available_bytes(tmp_path / "absent") is None


def test_a_size_beyond_free_memory_is_refused_with_both_figures() -> None:
    check("the replay", 2 * GIB, available=3 * GIB)  # fits: nothing said
    with pytest.raises(NotEnoughMemory, match=r"^the replay: at least 4\.0 GiB, 3\.0 GiB free$") as caught:
        check("the replay", 4 * GIB, available=3 * GIB)
    assert isinstance(caught.value, MemoryError)  # `collie train` names the sizes given for any MemoryError
