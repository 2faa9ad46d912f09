"""The update runs with denormal floats flushed to zero (trainer/denormals.py), and nothing else does."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import torch

from trainer.config import make_config
from trainer.denormals import flushing_denormals
from trainer.loop import Trainer

SMALLEST_NORMAL = torch.finfo(torch.float32).tiny


def flushes() -> bool:
    """Whether this thread flushes now: a quarter of the smallest normal float is a denormal."""
    return float(torch.tensor([SMALLEST_NORMAL]) * 0.25) == 0.0


@pytest.fixture(autouse=True)
def _x86() -> None:
    if not torch.set_flush_denormal(False):
        pytest.skip("this CPU cannot flush denormals")


def test_only_the_block_flushes_and_the_mode_is_restored_after_an_error() -> None:
    assert not flushes()
    with flushing_denormals(True):
        assert flushes()
    assert not flushes()
    with pytest.raises(RuntimeError), flushing_denormals(True):
        raise RuntimeError("inside")
    assert not flushes()
    with flushing_denormals(False):
        assert not flushes()


@pytest.mark.parametrize("on", [True, False])
def test_the_trainer_flushes_in_its_update_alone(tmp_path: Path, on: bool) -> None:
    cfg = make_config("smoke", "point", out=str(tmp_path), epochs=3, flush_denormal=on, threads=1)
    trainer = Trainer(cfg, progress=False)
    seen: dict[str, list[bool]] = {"update": [], "collect": []}
    update, collect = trainer.agent.update, trainer.collect_epoch

    def watched_update(*args: Any) -> Any:
        seen["update"].append(flushes())
        return update(*args)

    def watched_collect() -> None:
        seen["collect"].append(flushes())
        collect()

    trainer.agent.update = watched_update  # type: ignore[method-assign]
    trainer.collect_epoch = watched_collect  # type: ignore[method-assign]
    trainer.run()
    assert seen["update"] and set(seen["update"]) == {on}
    assert seen["collect"] and set(seen["collect"]) == {False}  # rollouts and MuJoCo keep IEEE arithmetic
    assert not flushes()


def test_runs_saved_before_the_option_keep_their_arithmetic() -> None:
    from trainer.config import Config

    stored = make_config("cpu", "point").to_dict()
    del stored["flush_denormal"]
    assert Config.from_stored(stored).flush_denormal is False


def test_flushing_or_not_is_the_same_run_to_sweeps_reports_and_archives() -> None:
    """Like the fused Adam kernel: the same mathematics, run faster; a sweep must not call a run
    saved before the option "another configuration" and refuse to extend it."""
    from trainer.same_run import differing_keys

    before = make_config("cpu", "point").to_dict()
    del before["flush_denormal"]
    assert differing_keys(before, make_config("cpu", "point").to_dict()) == []
