"""Cheap checkpoints: checkpoint.pt without the replay, the replay as append-only chunks that a
resume rebuilds exactly, and SIGTERM writing a final checkpoint that `--resume` continues exactly."""

import errno
import json
import pickle
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from paced_marks import PacedMarks
from small_disk import small_disk

from trainer.checkpoint import load_checkpoint, save_checkpoint
from trainer.config import make_config
from trainer.loop import Trainer
from trainer.replay import FIELDS, TrajectoryReplay
from trainer.replay_log import ReplayLog

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)
ROOT = Path(__file__).resolve().parents[2]  # the checkout under test (tests run in a scratch cwd)


def replay(size: int = 5) -> TrajectoryReplay:
    return TrajectoryReplay(size * 10, 10, 3, 2, 2, 2, 2)


def add(r: TrajectoryReplay, n: int, rng: np.random.Generator, epoch: int) -> None:
    t = r.steps + 1
    r.add(
        rng.normal(size=(n, t, 3)),
        rng.normal(size=(n, t - 1, 2)),
        rng.normal(size=(n, 2)),
        rng.normal(size=(n, t, 2)),
        rng.normal(size=(n, t)),
        rng.normal(size=(n, t, 2)),
        rng.normal(size=(n, t, 2)),
        epoch,
    )


def test_replay_log_writes_only_new_trajectories_and_restores_exactly(tmp_path):
    r, rng = replay(), np.random.default_rng(0)
    log = ReplayLog(tmp_path, r)
    add(r, 3, rng, 1)
    first = log.flush()
    log.prune()
    assert first["chunks"] == [0] and len(np.load(log.path(0))["slots"]) == 3
    add(r, 4, rng, 2)  # wraps the ring of 5: slots 3, 4, 0, 1
    record = log.flush()
    log.prune()
    assert record["chunks"] == [0, 1] and len(np.load(log.path(1))["slots"]) == 4  # slot 2 still from chunk 0
    add(r, 1, rng, 3)  # slot 2: chunk 0 is now dead
    record = log.flush()
    log.prune()
    assert record["chunks"] == [1, 2] and not log.path(0).exists()
    add(r, 2, rng, 4)  # written after the last checkpoint (a crash before the next one): not restored
    log.flush()

    fresh = replay()
    ReplayLog(tmp_path, fresh).restore(record)
    assert (fresh.next, fresh.count) == (3, 5)
    r_at_record = replay()
    log_b = ReplayLog(tmp_path / "b", r_at_record)
    rng = np.random.default_rng(0)
    for n, e in ((3, 1), (4, 2), (1, 3)):
        add(r_at_record, n, rng, e)
    for key in FIELDS:
        np.testing.assert_array_equal(getattr(fresh, key), getattr(r_at_record, key))
    assert log_b.flush()["count"] == 5


def test_checkpoint_holds_no_replay_and_stays_small(tmp_path):
    cfg = make_config("smoke", "ant", out=str(tmp_path), epochs=4, episode_steps=20, segment_length=5)
    t = Trainer(cfg, progress=False)
    t.run()
    ckpt = torch.load(tmp_path / "checkpoint.pt", weights_only=False)
    assert set(ckpt["replay"]) == {"chunks", "next", "count", "next_chunk"}
    replay_bytes = sum(getattr(t.replay, k)[: t.replay.count].nbytes for k in FIELDS)
    chunk_bytes = sum(f.stat().st_size for f in (tmp_path / "replay").glob("*.npz"))
    assert replay_bytes <= chunk_bytes < 1.2 * replay_bytes + 64_000  # each trajectory written once
    assert (tmp_path / "checkpoint.pt").stat().st_size < 2_000_000  # networks + optimisers of 2×64 nets


def test_sigterm_writes_a_final_checkpoint_and_resume_reproduces_the_run(tmp_path):
    straight, stopped = tmp_path / "straight", tmp_path / "stopped"
    common = dict(epochs=40, noise_band=2.0, checkpoint_every=1000, eval_every=4)
    a = Trainer(make_config("smoke", "point", out=str(straight), **common), progress=False)
    a.run()

    cmd = [sys.executable, "-m", "collie.cli", "train", "--preset", "smoke", "--out", str(stopped), "--no-progress"]
    cmd += [f"--{k.replace('_', '-')}={v}" for k, v in common.items()]
    marks = PacedMarks(tmp_path)  # the signal lands before the trainer's mark after epoch 4's evaluation
    env = {**marks.env, "PYTHONPATH": str(ROOT)}
    code, err = marks.run(cmd, lambda m: m.what == "evaluate" and m.epoch == 4, signal.SIGTERM, 300, env=env)
    assert code == 0, err[-3000:]
    summary = json.loads((stopped / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["epochs_done"] in (4, 5)
    assert torch.load(stopped / "checkpoint.pt", weights_only=False)["epoch"] == summary["epochs_done"]

    b = Trainer(make_config("smoke", "point", out=str(stopped), **common), progress=False)
    b.run(resume=True)
    for p, q in zip(a.agent.policy.parameters(), b.agent.policy.parameters(), strict=True):
        assert torch.equal(p, q)
    for p, q in zip(a.agent.phi.parameters(), b.agent.phi.parameters(), strict=True):
        assert torch.equal(p, q)
    rows = [json.loads(ln) for ln in (straight / "metrics.jsonl").read_text().splitlines()]
    resumed = [json.loads(ln) for ln in (stopped / "metrics.jsonl").read_text().splitlines()]
    strip = [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]
    assert strip == [{k: v for k, v in r.items() if k != "wall_s"} for r in resumed]


def test_a_checkpoint_that_cannot_be_written_leaves_the_last_one_and_no_partial_file(tmp_path):
    """As on a full disk: the save fails midway; the last good checkpoint stays resumable."""
    path = tmp_path / "checkpoint.pt"
    save_checkpoint(path, {"epoch": 1})
    with pytest.raises((pickle.PicklingError, AttributeError, TypeError)):
        save_checkpoint(path, {"epoch": 2, "unpicklable": lambda: None})
    assert load_checkpoint(path) == {"epoch": 1} and sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint.pt"]


def test_a_checkpoint_larger_than_the_disk_s_room_is_the_file_system_s_refusal(tmp_path):
    """torch's zip writer raised its own RuntimeError ("unexpected pos …") over the full disk's
    OSError, which `collie train` shows as a traceback (exit 1; `collie up` restarted it as a crash)."""
    with small_disk(tmp_path / "disk") as disk:
        save_checkpoint(disk / "checkpoint.pt", {"epoch": 1})
        with pytest.raises(OSError) as caught:
            save_checkpoint(disk / "checkpoint.pt", {"epoch": 2, "weights": torch.zeros(500_000)})  # 2 MB
        assert caught.value.errno == errno.ENOSPC
        assert load_checkpoint(disk / "checkpoint.pt") == {"epoch": 1}
        assert sorted(p.name for p in disk.iterdir()) == ["checkpoint.pt"]
