"""A smoke training run of every new method and ablation on real MuJoCo, exact resume of the
classifier baselines, and both downstream tasks on tiny trained runs."""

import json

import numpy as np
import pytest
import torch

from trainer.config import make_config
from trainer.diayn import Diayn
from trainer.downstream.__main__ import run_downstream
from trainer.loop import Trainer
from trainer.lsd import Lsd

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)


def smoke(out, **kw) -> Trainer:
    return Trainer(make_config("smoke", kw.pop("env", "point"), out=str(out), **kw), progress=False)


@pytest.mark.parametrize(
    ("method", "extra", "labels"),
    [
        ("diayn", {}, 0),
        ("lsd", {}, 0),
        ("dodont", {}, 4),
        ("ddg", {}, 4),
        ("collie", {"reward_form": "additive"}, 4),
        ("collie", {"distance": "l2"}, 4),
        ("collie", {"obs_noise": 0.1}, 4),
    ],
)
def test_smoke_run(tmp_path, method, extra, labels):
    t = smoke(tmp_path, method=method, task="north", epochs=4, **extra)
    summary = t.run()
    assert summary["status"] == "finished" and summary["n_labels"] == labels
    assert np.isfinite(summary["safe_coverage"]) and (tmp_path / "eval_latest.npz").exists()
    if method == "diayn":
        assert isinstance(t.agent, Diayn)
    if method == "lsd" or extra.get("distance") == "l2":
        assert isinstance(t.agent, Lsd)
    if method in ("dodont", "ddg"):
        assert t.instruction is not None and t.instruction.trained


def test_dodont_resumes_exactly(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    straight = smoke(a, method="dodont", epochs=6)
    straight.run()
    smoke(b, method="dodont", epochs=4).run()
    resumed = smoke(b, method="dodont", epochs=6)
    resumed.run(resume=True)
    for p, q in zip(straight.agent.policy.parameters(), resumed.agent.policy.parameters(), strict=True):
        assert torch.equal(p, q)
    for p, q in zip(straight.instruction.net.parameters(), resumed.instruction.net.parameters(), strict=True):
        assert torch.equal(p, q)


def test_downstream_tasks_on_tiny_runs(tmp_path):
    smoke(tmp_path / "point", method="collie", epochs=2).run()
    zs = run_downstream(tmp_path / "point", trajectories=6)["zero_shot"]
    assert zs["trajectories"] == 6 and zs["best"] >= zs["mean"]
    smoke(
        tmp_path / "hc",
        env="half_cheetah",
        task="not_flip",
        method="metra",
        epochs=1,
        episode_steps=50,
        episodes_per_epoch=2,
        eval_trajectories=2,
    ).run()
    hi = run_downstream(tmp_path / "hc", ppo_overrides={"envs": 2})["hierarchical"]
    assert len(hi["train_curve"]) == 2 and np.isfinite(hi["mean"]) and hi["ppo"]["hidden"] == 32  # smoke budget
    stored = json.loads((tmp_path / "hc" / "downstream.json").read_text())
    assert set(stored) == {"hierarchical"}
