"""Algorithm 1 end to end on real MuJoCo with the `smoke` preset: runs, spreads, resumes exactly,
fails loudly on bad input and on NaN."""

import hashlib
import json
import re
import subprocess
import sys
from collections.abc import Collection
from pathlib import Path

import numpy as np
import pytest
import torch

from collie.tasks import Task, get_task
from trainer.checkpoint import load_checkpoint, save_checkpoint
from trainer.config import make_config
from trainer.feedback import LabelEvent, OracleFeedback, Segment
from trainer.loop import Trainer, TrainingDiverged
from trainer.run_files import ResumeError
from trainer.telemetry import Reporter, StatusReport

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)


def smoke(out: Path, **kw) -> Trainer:
    cfg = make_config("smoke", kw.pop("env", "point"), out=str(out), **kw)
    return Trainer(cfg, progress=False)


def records(out: Path) -> list[dict]:
    return [json.loads(ln) for ln in (out / "metrics.jsonl").read_text().splitlines()]


def test_smoke_run_writes_outputs_and_skills_spread(tmp_path):
    summary = smoke(tmp_path, method="collie", task="north").run()
    rec = records(tmp_path)
    assert rec[0]["epoch"] == 0 and rec[-1]["epoch"] == 8
    assert rec[-1]["n_bins"] > rec[0]["n_bins"]  # evaluation coverage above epoch 0's
    assert summary["n_labels"] == 6 and summary["status"] == "finished"
    for key in (
        "epoch",
        "env_steps",
        "safe_coverage",
        "safe_ratio",
        "composite_coverage",
        "weighted_composite_coverage",
        "n_labels",
        "lambda",
        "wall_s",
    ):
        assert key in rec[-1] and key in summary
    assert summary["config"]["method"] == "collie"
    for name in ("skills_latest.png", "curves.png", "checkpoint.pt", "config.json"):
        assert (tmp_path / name).stat().st_size > 0
    assert any((tmp_path / "tb").iterdir())


@pytest.mark.parametrize("method", ["metra", "oracle"])
def test_baseline_methods_ask_no_labels(tmp_path, method):
    summary = smoke(tmp_path, method=method, task="hole_north").run()
    assert summary["n_labels"] == 0 and summary["status"] == "finished"


def test_resume_reproduces_the_next_epochs_exactly(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    straight = smoke(a, epochs=6, noise_band=2.0)
    straight.run()
    first = smoke(b, epochs=4, noise_band=2.0)
    first.run()
    resumed = smoke(b, epochs=6, noise_band=2.0)
    resumed.run(resume=True)
    for p, q in zip(straight.agent.policy.parameters(), resumed.agent.policy.parameters(), strict=True):
        assert torch.equal(p, q)
    assert torch.equal(straight.agent.log_lambda, resumed.agent.log_lambda)
    assert straight.labelled.counts() == resumed.labelled.counts()
    strip = [{k: v for k, v in r.items() if k != "wall_s"} for r in records(a)]
    assert strip == [{k: v for k, v in r.items() if k != "wall_s"} for r in records(b)]


def test_acting_torch_reaches_the_rollouts_and_is_deterministic(tmp_path):
    """`--acting torch` changes only rounding, but it must reach the trainer's rollouts: its runs
    repeat themselves exactly and differ (in the last floats) from the default path's."""
    runs = {}
    for name, acting in (("fast", "fast"), ("torch", "torch"), ("torch2", "torch")):
        runs[name] = smoke(tmp_path / name, epochs=4, acting=acting)  # each seeds torch as it starts
        runs[name].run()
    params = {name: torch.cat([p.flatten() for p in t.agent.policy.parameters()]) for name, t in runs.items()}
    assert torch.equal(params["torch"], params["torch2"])
    assert not torch.equal(params["torch"], params["fast"])
    assert torch.allclose(params["torch"], params["fast"], atol=0.5)  # the same learning, other floats


def test_nan_stops_the_run_naming_the_epoch_and_keeps_the_checkpoint(tmp_path):
    t = smoke(tmp_path, epochs=4)
    t.run()
    ckpt = tmp_path / "checkpoint.pt"
    digest = hashlib.sha256(ckpt.read_bytes()).hexdigest()
    with torch.no_grad():
        t.agent.phi.net[0].weight[0, 0] = float("nan")
    t.epoch += 1
    with pytest.raises(TrainingDiverged, match=r"non-finite .*phi_loss.* at epoch 5; last checkpoint kept"):
        t.train_epoch()
    with torch.no_grad():
        t.agent.policy.trunk[0].weight.fill_(float("nan"))
    with pytest.raises(TrainingDiverged, match="non-finite action at epoch 5"):
        t.collect_epoch()
    assert hashlib.sha256(ckpt.read_bytes()).hexdigest() == digest


def test_a_run_that_diverges_ends_failed_in_its_summary_and_keeps_its_checkpoint(tmp_path):
    t = smoke(tmp_path, epochs=4)
    t.run()
    digest = hashlib.sha256((tmp_path / "checkpoint.pt").read_bytes()).hexdigest()
    t.cfg.epochs = 6
    with torch.no_grad():
        t.agent.phi.net[0].weight[0, 0] = float("nan")
    with pytest.raises(TrainingDiverged, match="at epoch 5"):
        t.run()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "failed" and "non-finite" in summary["error"]  # not the "finished" of epoch 4
    assert hashlib.sha256((tmp_path / "checkpoint.pt").read_bytes()).hexdigest() == digest


def test_a_checkpoint_with_non_finite_values_is_refused_naming_them(tmp_path):
    smoke(tmp_path, epochs=2).run()
    state = load_checkpoint(tmp_path / "checkpoint.pt")
    state["agent"]["qf"]["layers.0.weight"].view(-1)[7] = float("nan")  # as a flipped bit reads
    save_checkpoint(tmp_path / "checkpoint.pt", state)
    with pytest.raises(ResumeError, match=r"non-finite values \(agent\.qf\.layers\.0\.weight\): it is damaged"):
        smoke(tmp_path, epochs=4).resume()


@pytest.mark.parametrize(
    ("flag", "value", "names"),
    [
        ("--env", "mars", "point"),
        ("--task", "south", "north"),
        ("--method", "ppo", "collie"),
        ("--preset", "huge", "smoke"),
        ("--query-strategy", "random", "entropy"),
    ],
)
def test_cli_bad_names_are_clear_errors(tmp_path, flag, value, names):
    cmd = [sys.executable, "-m", "collie.cli", "train", "--preset", "smoke", "--out", str(tmp_path), flag, value]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert value in proc.stderr and names in proc.stderr and "valid" in proc.stderr


def test_cli_runs_and_overrides(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "collie.cli",
        "train",
        "--preset",
        "smoke",
        "--out",
        str(tmp_path),
        "--epochs",
        "3",
        "--hidden",
        "16",
        "--no-progress",
        "--task",
        "range",
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    cfg = json.loads((tmp_path / "config.json").read_text())
    assert cfg["epochs"] == 3 and cfg["hidden"] == 16 and cfg["task"] == "range"
    assert json.loads(proc.stdout.splitlines()[0])["epoch"] == 3


@pytest.mark.parametrize("env", ["ant", "half_cheetah"])
def test_smoke_runs_on_locomotion_envs(tmp_path, env):
    task = "not_flip" if env == "half_cheetah" else "hole"
    summary = smoke(
        tmp_path,
        env=env,
        task=task,
        epochs=2,
        episode_steps=20,
        episodes_per_epoch=2,
        eval_trajectories=4,
        segment_length=5,
        warmup=1,
        feedback_every=1,
    ).run()
    assert summary["status"] == "finished" and np.isfinite(summary["safe_coverage"])


def test_a_moved_run_folder_resumes_where_it_is_now(tmp_path):
    train = [sys.executable, "-m", "collie.cli", "train", "--env", "point", "--preset", "smoke", "--no-progress"]
    first = subprocess.run([*train, "--epochs", "2", "--out", str(tmp_path / "was")], capture_output=True, text=True)
    assert first.returncode == 0, first.stderr[-2000:]
    (tmp_path / "was").rename(tmp_path / "now")
    again = subprocess.run(
        [*train, "--epochs", "4", "--out", str(tmp_path / "now"), "--resume"], capture_output=True, text=True
    )
    assert again.returncode == 0, again.stderr[-2000:]
    summary = json.loads((tmp_path / "now" / "summary.json").read_text())
    assert summary["epoch"] == 4 and summary["config"]["out"] == str(tmp_path / "now")
    assert not (tmp_path / "was").exists()


def test_a_refusal_met_in_the_last_epoch_is_said_after_the_run_is_saved(tmp_path):
    """A source that was refused after the last epoch's control() (its revisions call) has no next
    control() to raise it: the finished run still says so, not exit 0 with the service untold."""
    from trainer.feedback import SourceRefused

    t = smoke(tmp_path, epochs=2)
    t.feedback.refusal = SourceRefused("the labeling service refused the trainer's token for run 1 (401)")
    with pytest.raises(SourceRefused, match="the run finished, but the service was not told"):
        t.run()
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "finished"


class LateLastSession(OracleFeedback):
    """The oracle, but the last session's labels come only once the run was reported over, as labels
    given after a feedback timeout do until the service closes the run."""

    def __init__(self, task: Task, last: int) -> None:
        super().__init__(task)
        self.last, self.held, self.closed = last, list[LabelEvent](), False

    def collect(self, session: int, epoch: int, segments: list[Segment]) -> list[LabelEvent]:
        events = super().collect(session, epoch, segments)
        if session != self.last:
            return events
        self.held = events
        return []

    def revisions(self) -> list[LabelEvent]:
        late, self.held = (self.held, []) if self.closed else ([], self.held)
        return late


class ClosingReporter(Reporter):
    def __init__(self, feedback: LateLastSession) -> None:
        self.feedback = feedback

    def status(self, report: StatusReport) -> None:
        self.feedback.closed = self.feedback.closed or report.status == "finished"


def test_labels_that_come_after_the_last_update_are_applied_before_the_run_ends(tmp_path):
    """Was: the service counted them (given before it closed the run), but the trainer's last pull
    came at the start of its last epoch: its final checkpoint held fewer labels than the service."""
    cfg = make_config("smoke", "point", out=str(tmp_path))
    feedback = LateLastSession(get_task(cfg.task, "point"), cfg.n_sessions - 1)
    trainer = Trainer(cfg, feedback=feedback, progress=False, reporter=ClosingReporter(feedback))
    assert trainer.run()["status"] == "finished"
    labelled = load_checkpoint(tmp_path / "checkpoint.pt")["labelled"]
    assert len(labelled) == cfg.total_queries and feedback.held == []


class ForgetfulService(OracleFeedback):
    """A source of truth that holds no label: a service whose database is older than the checkpoint."""

    def history(self, held: Collection[str] = ()) -> list[tuple[Segment, int]]:
        return []


def test_a_resume_whose_service_lacks_labels_the_checkpoint_applied_says_so(tmp_path, capsys):
    """Was silent: a database restored from a backup dropped every label given since, on both sides."""
    smoke(tmp_path).run()
    cfg = make_config("smoke", "point", out=str(tmp_path), epochs=7)
    before = load_checkpoint(tmp_path / "checkpoint.pt")["labelled"]
    Trainer(cfg, feedback=ForgetfulService(get_task(cfg.task, "point")), progress=False).run(resume=True)
    said = capsys.readouterr().err
    assert f"the labeling service holds no label for {len(before)} segment(s) this checkpoint had applied" in said
    assert "(restored from a backup?)" in said and len(before) > 0


def test_a_live_run_redraws_its_curves_at_an_evaluation_not_only_at_its_end(tmp_path, monkeypatch):
    """Was: curves.png only from finish(): a run still training, or killed, had none."""
    import trainer.loop

    monkeypatch.setattr(trainer.loop, "CURVES_EVERY_S", 0.0)
    run = smoke(tmp_path, method="metra", task="north", epochs=4)
    drawn: list[int] = []
    plot = run.plot_curves
    monkeypatch.setattr(run, "plot_curves", lambda records=None: (drawn.append(run.epoch), plot(records))[1])
    evaluate = run.evaluate

    def evaluate_and_look() -> dict:
        record = evaluate()
        assert (tmp_path / "curves.png").stat().st_size > 0 and not (tmp_path / "summary.json").exists()
        return record

    monkeypatch.setattr(run, "evaluate", evaluate_and_look)
    run.run()
    assert drawn[:-1] == [r["epoch"] for r in records(tmp_path)]  # each evaluation's, then finish()'s


def test_the_progress_bar_says_the_epochs_before_any_update_are_start_transitions(tmp_path, capsys):
    """Was: "training" and an ETA from rollouts alone (a pixel paper run said 5 h for weeks)."""
    from trainer.config import make_config

    cfg = make_config("smoke", "point", out=str(tmp_path), method="metra", epochs=4, start_transitions=400)
    steps_per_epoch = cfg.episodes_per_epoch * cfg.episode_steps
    assert steps_per_epoch < 400 <= 3 * steps_per_epoch  # some epochs of rollouts alone, then updates
    Trainer(cfg, progress=True).run()
    err = capsys.readouterr().err
    assert "collecting 400 start transitions" in err and "training" in err.split("collecting 400 start transitions")[-1]


def test_a_log_hears_the_runs_pace_between_evaluations(tmp_path, capsys, monkeypatch):
    """Was: nothing between evaluations (a robot's cpu preset evaluates minutes apart)."""
    import trainer.loop

    monkeypatch.setattr(trainer.loop, "HEARTBEAT_S", 0.0)
    smoke(tmp_path, method="metra", task="north", epochs=4, start_transitions=0).run()
    paced = [ln for ln in capsys.readouterr().err.splitlines() if "epochs/min" in ln]
    assert paced and all(
        re.fullmatch(r"epoch [123]/4 · [\d.]+ epochs/min · about under a minute left at this pace", ln) for ln in paced
    )


def test_the_bars_label_count_follows_each_feedback_session(tmp_path, capsys):
    """Was: the count of the last evaluation's (labels=5 at epoch 11 with 10 in)."""
    Trainer(
        make_config("smoke", "point", out=str(tmp_path), method="collie", task="north", epochs=8), progress=True
    ).run()
    shown = [int(n) for n in re.findall(r"labels=(\d+)", capsys.readouterr().err)]
    assert shown == sorted(shown) and 2 in shown  # the first session's 2 labels (epoch 2): no evaluation shows them
