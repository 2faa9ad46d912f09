"""The `cpu` budgets for Ant and HalfCheetah: written-down shape, the paper's feedback proportions,
and a small Ant run of that shape that trains, asks for labels, logs both bin rules and resumes."""

import argparse
import json
import shlex
from pathlib import Path

import pytest
import torch

from trainer.cli import add_arguments, config_from_args
from trainer.config import ROBOT_CPU, feedback_schedule, make_config, people_schedule
from trainer.loop import Trainer
from trainer.obs_stats import REFERENCE_STATS


@pytest.mark.parametrize(("env", "epochs"), [("ant", 2000), ("half_cheetah", 1600)])
def test_cpu_robot_budget_and_feedback_proportions(env: str, epochs: int) -> None:
    c = make_config("cpu", env)
    assert (c.epochs, c.grad_steps, c.hidden, c.layers, c.lr, c.batch_size) == (epochs, 50, 256, 2, 1e-3, 256)
    assert c.epochs * c.episodes_per_epoch * c.episode_steps == epochs * 1600  # env steps
    assert c.obs_norm == "reference"
    # The paper's proportions: warm-up 20 %, K = 10 %, 8 sessions of M = 5, N_total = 40, H = 20.
    assert (c.warmup, c.feedback_every) == (epochs // 5, epochs // 10)
    assert (c.queries_per_session, c.total_queries, c.n_sessions, c.segment_length) == (5, 40, 8, 20)
    last_session = c.warmup + (c.n_sessions - 1) * c.feedback_every
    assert last_session == int(0.9 * epochs) < c.epochs
    assert make_config("cpu", "point").epochs == 400  # the point-mass preset is untouched
    assert ROBOT_CPU[env]["epochs"] == epochs


def test_feedback_schedule_scales_and_refuses_what_does_not_fit() -> None:
    assert feedback_schedule(10_000) == {"warmup": 2000, "feedback_every": 1000}  # Table 6
    assert feedback_schedule(10) == {"warmup": 2, "feedback_every": 1}
    with pytest.raises(ValueError, match="sessions"):
        feedback_schedule(7)
    assert feedback_schedule(2000, first=240) == {"warmup": 240, "feedback_every": 222}  # last at 1794
    with pytest.raises(ValueError, match="sessions"):
        feedback_schedule(100, first=95)


def test_people_label_ant_from_epoch_240_and_the_last_session_stays_at_ninety_percent() -> None:
    schedule = people_schedule("cpu", "ant")
    c = make_config("cpu", "ant", **schedule)
    assert make_config("cpu", "ant").warmup == 400 and c.warmup == 240  # ≈ 14 min of waiting → ≈ 9
    last_session = c.warmup + (c.n_sessions - 1) * c.feedback_every
    assert c.n_sessions == 8 and 0.85 * c.epochs < last_session <= 0.9 * c.epochs
    for preset, env in (("cpu", "point"), ("cpu", "half_cheetah"), ("paper", "ant")):
        assert people_schedule(preset, env) == {}  # the preset's own schedule


@pytest.mark.parametrize(
    ("argv", "schedule"),
    [
        ("--env ant --people-schedule", (2000, 240, 222)),  # what `collie up` passes when people label
        ("--env ant", (2000, 400, 200)),  # the scripted teacher and the sweeps: the preset's
        ("--env ant --people-schedule --epochs 50 --warmup 10 --feedback-every 5", (50, 10, 5)),  # their own
        ("--env ant --people-schedule --warmup 300", (2000, 300, 200)),
        ("--env point --people-schedule", (400, 40, 25)),  # make demo: the preset asks early already
    ],
)
def test_collie_train_brings_the_first_session_forward_only_for_people(argv: str, schedule: tuple) -> None:
    p = argparse.ArgumentParser()
    add_arguments(p)
    c = config_from_args(p.parse_args(shlex.split(argv)))
    assert (c.epochs, c.warmup, c.feedback_every) == schedule


@pytest.mark.parametrize(("env", "task"), [("point", "north"), ("half_cheetah", "right"), ("car", "hazard")])
def test_collie_train_without_a_task_runs_its_envs_own(env: str, task: str) -> None:
    """North has no meaning on HalfCheetah's line or the car's floor: each gets the paper's first task."""
    p = argparse.ArgumentParser()
    add_arguments(p)
    c = config_from_args(p.parse_args(["--env", env]))
    assert c.task == task and c.out == f"runs/{env}-{task}-collie-s0"
    assert make_config("cpu", env).task == task


def small_ant(out: Path, epochs: int) -> Trainer:
    """The cpu Ant preset's shape (schedule proportions, M, N_total, obs statistics), shrunk."""
    cfg = make_config(
        "cpu",
        "ant",
        method="collie",
        task="north",
        out=str(out),
        epochs=epochs,
        **feedback_schedule(10),
        hidden=32,
        batch_size=32,
        grad_steps=2,
        episodes_per_epoch=2,
        episode_steps=25,
        start_transitions=50,
        replay_capacity=2_000,
        candidates=10,
        eval_every=5,
        eval_trajectories=4,
        checkpoint_every=3,
        threads=1,
    )
    return Trainer(cfg, progress=False)


def test_small_ant_run_of_the_robot_shape_trains_and_resumes(tmp_path: Path) -> None:
    straight = small_ant(tmp_path / "a", 10)
    assert straight.normalise.std[0] == pytest.approx(REFERENCE_STATS["ant"][1][0])  # METRA's preset
    summary = straight.run()
    assert summary["status"] == "finished" and summary["n_labels"] == 40  # 8 sessions × 5 at epochs 2…9
    for key in (
        "corner_safe_coverage",
        "visited_safe_coverage",
        "corner_safe_ratio",
        "visited_n_bins",
        "final_x_spread",
    ):
        assert key in summary
    first = small_ant(tmp_path / "b", 6)
    first.run()
    resumed = small_ant(tmp_path / "b", 10)
    resumed.run(resume=True)
    for p, q in zip(straight.agent.policy.parameters(), resumed.agent.policy.parameters(), strict=True):
        assert torch.equal(p, q)
    assert straight.labelled.counts() == resumed.labelled.counts()

    def records(out: Path) -> list[dict]:
        rows = [json.loads(ln) for ln in (out / "metrics.jsonl").read_text().splitlines()]
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]

    resumed_rows = [r for r in records(tmp_path / "b") if r["epoch"] != 6]  # the first part's last evaluation
    assert records(tmp_path / "a") == resumed_rows
    assert "corner_safe_coverage" in records(tmp_path / "a")[-1]
