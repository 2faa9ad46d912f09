"""`collie train` on ordinary mistakes: one line `collie train: error: …` naming the flag or file, exit 2,
and no run folder overwritten or created by a refused command."""

from __future__ import annotations

import argparse
import errno
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
from paced_marks import PacedMarks
from small_disk import fill, small_disk
from unprivileged import as_nobody, closed_folder

from collie.schemas import StartupMark
from trainer.cli import short_of_memory
from trainer.fast_ops import fast_ops_pay
from trainer.loop import coverage_shown, evaluation_line

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)

TRAIN = [sys.executable, "-m", "collie.cli", "train", "--env", "point", "--preset", "smoke", "--no-progress"]


def train(*args: str, timeout: float = 300, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=timeout, env=env)


def refused(proc: subprocess.CompletedProcess[str], *words: str) -> str:
    """The one-line error, checked: exit 2, no traceback, every word in it."""
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith("collie train: error: "), proc.stderr
    for word in words:
        assert word in line, line
    return line


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real 2-epoch smoke run (checkpoint, replay chunk, metrics, summary)."""
    out = tmp_path_factory.mktemp("finished") / "run"
    proc = train("--epochs", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def test_the_progress_bar_says_the_safe_coverage_as_a_whole_number() -> None:
    """Was "safe_cov=-2e+3": tqdm shows a float postfix to 3 significant digits."""
    assert coverage_shown({"safe_coverage": -1834.6}) == "-1835"
    assert coverage_shown({"safe_coverage": 352.0}) == "352"
    assert coverage_shown({}) == "-"  # a run without a rule has none
    line = evaluation_line(40, 400, {"safe_coverage": 1834.0, "n_bins": 1340.0}, 12)
    assert line == "epoch 40/400 · safe cov 1834 · bins 1340 · labels 12"


def test_a_run_without_a_progress_bar_logs_a_line_per_evaluation(tmp_path: Path) -> None:
    """A sweep's runs and collie up's trainer draw no bar: their logs held nothing for hours."""
    proc = train("--task", "north", "--epochs", "2", "--out", str(tmp_path / "run"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = [line for line in proc.stderr.splitlines() if line.startswith("epoch ")]
    assert [line.split(" · ")[0] for line in lines] == ["epoch 2/2"], proc.stderr[-3000:]
    assert re.fullmatch(r"epoch 2/2 · safe cov -?\d+ · bins \d+ · labels \d+", lines[0]), lines


@pytest.fixture
def run_copy(finished: Path, tmp_path: Path) -> Path:
    """A copy of the finished run that a test may damage."""
    return Path(shutil.copytree(finished, tmp_path / "run"))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_an_existing_run_is_not_overwritten_without_resume(run_copy: Path) -> None:
    before = {p.name: digest(p) for p in run_copy.iterdir() if p.is_file()}
    refused(train("--epochs", "1", "--out", str(run_copy)), "already holds a run", "--resume", "--out")
    assert {p.name: digest(p) for p in run_copy.iterdir() if p.is_file()} == before


def test_a_run_whose_checkpoint_is_gone_is_told_to_start_again_elsewhere(run_copy: Path) -> None:
    """Was: --resume said "nothing to resume", and without it "add --resume to continue it"."""
    (run_copy / "checkpoint.pt").unlink()
    line = refused(train("--epochs", "3", "--out", str(run_copy), "--resume"), "holds a run but no checkpoint.pt")
    assert line.endswith("start it again in another --out (or remove this one)"), line
    line = refused(train("--epochs", "3", "--out", str(run_copy)), "already holds a run")
    assert line.endswith("it has no checkpoint.pt to continue it from: choose another --out (or remove it)"), line


def test_a_damaged_summary_does_not_stop_a_resume(run_copy: Path) -> None:
    """summary.json is the run's report, rewritten as it goes; the checkpoint is what it resumes from
    (was: "summary.json: not JSON", and no way on but to delete it)."""
    (run_copy / "summary.json").write_text("garbage")
    proc = train("--epochs", "3", "--out", str(run_copy), "--resume")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert json.loads((run_copy / "summary.json").read_text())["epochs_done"] == 3


def test_service_flags_without_a_service_are_refused_and_create_nothing(tmp_path: Path) -> None:
    """Was: trained offline, the flags ignored (a forgotten or misspelt --api among them)."""
    out = tmp_path / "offline"
    refused(train("--out", str(out), "--run-id", "3"), "--run-id is for a run on a labeling service: give --api")
    said = "--feedback-timeout, --token-file are for a run on a labeling service: give --api too (or drop them)"
    refused(train("--out", str(out), "--token-file", "/nonexistent", "--feedback-timeout", "5"), said)
    assert not out.exists()


def test_resume_without_a_checkpoint_is_refused_and_creates_nothing(tmp_path: Path) -> None:
    out = tmp_path / "never"
    refused(train("--out", str(out), "--resume"), "--resume", "no checkpoint", str(out / "checkpoint.pt"))
    assert not out.exists()
    (out / "checkpoint.pt").mkdir(parents=True)  # was "no checkpoint at": there is something, and not one
    refused(train("--out", str(out), "--resume"), f"--resume: {out / 'checkpoint.pt'} is a folder, not a checkpoint")


@pytest.mark.parametrize("where", ["file", "under_file"])
def test_out_that_is_or_lies_under_a_file_is_refused(tmp_path: Path, where: str) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    out = blocker if where == "file" else blocker / "run"
    refused(train("--epochs", "1", "--out", str(out)), "--out", "is a file")


@pytest.mark.parametrize(
    ("mode", "said"),
    [
        (0o555, "--out {run}: cannot write in {closed} (permission denied)"),
        (0o000, "--out {run}: cannot enter {closed} (permission denied)"),
    ],  # stat() refused: no traceback
)
def test_out_in_a_folder_this_user_may_not_write_or_enter_is_refused(mode: int, said: str) -> None:
    from collie.cli import main

    with closed_folder(mode) as closed:
        run = closed / "run"
        train_here = ["train", "--env", "point", "--preset", "smoke", "--out", str(run)]
        code, err = as_nobody(lambda: main(train_here), preload=("trainer.cli", "trainer.envs"))
        assert code == 2 and said.format(run=run, closed=closed) in err and "Traceback" not in err, err
        assert not run.exists()


def test_out_where_nobody_may_write_is_refused() -> None:
    refused(train("--epochs", "1", "--out", "/sys/collie-run"), "--out /sys/collie-run", "cannot")  # root too


def test_a_truncated_checkpoint_is_named(run_copy: Path) -> None:
    ckpt = run_copy / "checkpoint.pt"
    ckpt.write_bytes(ckpt.read_bytes()[:100])
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), str(ckpt), "damaged")


def test_a_missing_replay_chunk_is_named(run_copy: Path) -> None:
    chunk = next((run_copy / "replay").glob("*.npz"))
    chunk.unlink()
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), str(chunk), "missing")


def test_a_torn_last_metrics_line_is_dropped_and_a_missing_config_json_is_the_checkpoints_on_resume(
    run_copy: Path,
) -> None:
    """Two damages that each let the run resume (one resume shows both): the torn last line of a
    crash while appending is dropped, and a run without its config.json resumes with its
    checkpoint's config."""
    metrics = run_copy / "metrics.jsonl"
    whole = metrics.read_text()
    metrics.write_text(whole + '{"epoch": 3, "safe_cov')  # a crash while appending
    (run_copy / "config.json").unlink()
    proc = train("--out", str(run_copy), "--resume", "--epochs", "3", "--preset", "cpu")  # cpu: other net sizes
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert [json.loads(ln)["epoch"] for ln in metrics.read_text().splitlines()] == [0, 2, 3]
    assert json.loads((run_copy / "summary.json").read_text())["epochs_done"] == 3
    assert json.loads((run_copy / "config.json").read_text())["hidden"] == 64  # smoke's, from the checkpoint


def test_a_damaged_metrics_line_before_the_last_is_named(run_copy: Path) -> None:
    metrics = run_copy / "metrics.jsonl"
    metrics.write_text("{oops\n" + metrics.read_text())
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), str(metrics), "line 1")


@pytest.mark.parametrize(
    ("flag", "value", "words"),
    [
        ("--device", "bogus", ("--device", "'bogus'", "valid", "cpu")),
        ("--checkpoint-every", "0", ("--checkpoint-every", "≥ 1")),
        ("--skill-dim", "0", ("--skill-dim", "≥ 1")),
        ("--api", "notaurl", ("--api", "http://")),
        ("--gamma", "2", ("--gamma", "(0, 1]")),
        ("--total-queries", "-1", ("--total-queries", "≥ 0")),
        ("--lr", "0", ("--lr", "> 0")),
        ("--lr", "inf", ("--lr", "finite", "inf")),  # was accepted
        ("--target-entropy-scale", "nan", ("--target-entropy-scale", "finite")),
        ("--eval-trajectories", "0", ("--eval-trajectories", "≥ 1")),  # was "num_envs must be >= 1" later
        ("--batch-size", "6000", ("--batch-size 6000", "--replay-capacity 5000")),  # was accepted
        (
            "--start-transitions",
            "6000",
            ("--start-transitions 6000", "--replay-capacity 5000"),
        ),  # was: no step, "finished"
        ("--instruction", "", ("--instruction is empty",)),  # was "unknown task 'instruction'"
    ],
)
def test_bad_values_are_refused_before_training(tmp_path: Path, flag: str, value: str, words: tuple[str, ...]) -> None:
    refused(train("--epochs", "1", "--out", str(tmp_path / "run"), flag, value, timeout=60), *words)
    assert not (tmp_path / "run").exists()


def test_a_run_whose_sizes_leave_its_learning_or_its_labels_undone_says_so() -> None:
    """Was silent: a COLLIE run that asked for no label finished as METRA, and one whose first
    gradient step lay past its last epoch reported "finished"."""
    from trainer.cli import idle_parts
    from trainer.config import make_config

    assert idle_parts(make_config("smoke", "point", method="collie")) == []
    assert idle_parts(make_config("smoke", "point", method="collie", warmup=8)) == []  # a session at its last epoch
    assert idle_parts(make_config("smoke", "point", method="collie", warmup=9)) == [
        "collie asks for no label in this run (--warmup 9 > --epochs 8): it learns as METRA does"
    ]
    assert idle_parts(make_config("smoke", "point", method="collie", total_queries=0))[0].endswith(
        "(--total-queries 0): it learns as METRA does"
    )
    assert idle_parts(make_config("smoke", "point", method="metra", warmup=8)) == []  # asks for none anyway
    with pytest.raises(ValueError, match="must be ≤ the 5000 transitions --replay-capacity 5049 holds"):
        make_config("smoke", "point", start_transitions=5040, replay_capacity=5049)  # whole episodes of 50 only
    assert idle_parts(make_config("smoke", "point", method="metra", start_transitions=5000)) == [
        "no gradient step in this run: --start-transitions 5000 is more than the 1600 transitions its 8 epochs collect"
    ]


def test_device_cuda_without_cuda_is_refused(tmp_path: Path) -> None:
    hidden = {**os.environ, "CUDA_VISIBLE_DEVICES": ""}  # no CUDA device, on any machine
    out = str(tmp_path / "run")
    refused(train("--epochs", "1", "--out", out, "--device", "cuda", env=hidden), "--device cuda", "no CUDA")
    beyond = f"cuda:{torch.cuda.device_count()}"  # one past this machine's last device
    refused(train("--epochs", "1", "--out", out, "--device", beyond), f"--device {beyond}", "CUDA devices")
    assert not (tmp_path / "run").exists()


TOKENS = {"operator": "op-" + "o" * 30, "trainer": "tr-" + "t" * 30, "labeler": "lb-" + "l" * 30}


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A real labeling service; yields its URL."""
    tmp = tmp_path_factory.mktemp("service")
    info = tmp / "service.json"
    env = {**os.environ, **{f"COLLIE_{k.upper()}_TOKEN": v for k, v in TOKENS.items()}}
    cmd = [sys.executable, "-m", "collie.cli", "serve", "--port", "0", "--db", str(tmp / "c.db")]
    with open(tmp / "service.log", "wb") as log:
        proc = subprocess.Popen([*cmd, "--tokens-json", str(info)], stdout=log, stderr=subprocess.STDOUT, env=env)
    try:
        deadline = time.monotonic() + 120
        while not info.exists():
            assert proc.poll() is None and time.monotonic() < deadline, (tmp / "service.log").read_text()
            time.sleep(0.2)
        yield json.loads(info.read_text())["api"]
    finally:
        proc.terminate()
        proc.wait(timeout=30)


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (("--token", "wrong-" + "x" * 30), ("401",)),
        (("--token", TOKENS["labeler"]), ("403",)),
        (("--token", TOKENS["trainer"], "--run-id", "999"), ("404",)),
    ],
)
def test_the_service_refusal_is_one_line(tmp_path: Path, service: str, extra: tuple[str, ...], words) -> None:
    proc = train("--epochs", "1", "--out", str(tmp_path / "run"), "--api", service, *extra, timeout=120)
    refused(proc, "labeling service", service, *words)


def test_epochs_beyond_what_the_service_stores_are_refused_before_it_is_asked(tmp_path: Path) -> None:
    """Was pydantic's multi-line "1 validation error for RunCreate"; the bound is argparse's."""
    proc = train("--epochs", "99999999999999999999", "--out", str(tmp_path / "run"), "--api", "http://127.0.0.1:9")
    refused(proc, "--epochs", "more than 2147483647")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("pages", [1, 2])
def test_a_run_made_on_the_service_that_its_folder_cannot_remember_is_marked_failed(
    tmp_path: Path, service: str, pages: int
) -> None:
    """A disk with room for the lock but not for run_creation.json: no run is made. With room for
    that but not for service_run.json: the run was made on the service, no folder remembered it, and
    the dashboard showed it "created" for good (the next start made another). It is now marked
    failed, saying why."""
    from collie.client import CollieClient

    with small_disk(tmp_path / "disk") as disk, CollieClient(service, TOKENS["operator"]) as operator:
        before = {r.id for r in operator.runs(limit=1000)}
        room = os.statvfs(disk)
        (disk / "filler").write_bytes(b"\0" * (room.f_bavail - pages) * room.f_frsize)
        proc = api_train(service, "--epochs", "1", "--out", str(disk / "run"))
        refused(proc, f"cannot start the run in {disk / 'run'}: no space left on device")
        made = {r.id for r in operator.runs(limit=1000)} - before
        if pages == 1:
            assert not made
            return
        (newest,) = made
        assert operator.run(newest).status == "failed"
        assert not (disk / "run" / "run_creation.json").exists()  # sent again, it would answer that failed run
        said = [e.data.message or "" for e in operator.events(newest).events if e.kind == "status"]
        assert any(m.startswith(f"its trainer could not write {disk / 'run' / 'service_run.json'}") for m in said)


def api_train(service: str, *args: str) -> subprocess.CompletedProcess[str]:
    """A METRA smoke run through the service (it asks no labels: nobody need answer)."""
    return train("--method", "metra", "--api", service, "--token", TOKENS["trainer"], *args)


@dataclass(frozen=True)
class Trained:
    out: Path  # the run folder
    proc: subprocess.CompletedProcess[str]  # the `collie train` that made it, ended with exit 0


@pytest.fixture(scope="module")
def metra_run(service: str, tmp_path_factory: pytest.TempPathFactory) -> Trained:
    """A finished 2-epoch METRA run the service holds; its folder's service_run.json names it."""
    out = tmp_path_factory.mktemp("service_run") / "run"
    proc = api_train(service, "--epochs", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-3000:]
    return Trained(out, proc)


def test_resume_with_another_run_than_the_folders_is_refused(service: str, metra_run: Trained, tmp_path: Path) -> None:
    """Was resumed silently into run N: the checkpoint went on with another run's task and labels."""
    from collie.client import CollieClient
    from collie.schemas import RunCreate

    run = Path(shutil.copytree(metra_run.out, tmp_path / "run"))
    mine = json.loads((run / "service_run.json").read_text())["run_id"]
    with CollieClient(service, TOKENS["trainer"]) as client:  # another run on the service, of other config
        held = client.run(mine)  # (seed 1): as `collie train --seed 1 --epochs 1` would create it
        config = held.config | {"seed": 1, "epochs": 1}
        made = {k: getattr(held, k) for k in ("env", "task", "method", "dims", "n_total", "task_definition")}
        theirs = client.create_run(RunCreate(**made, config=config, epochs_total=1)).id
    proc = api_train(service, "--out", str(run), "--resume", "--epochs", "3", "--run-id", str(theirs))
    refused(proc, f"{run} belongs to run {mine} on {service}", f"not run {theirs}", f"--run-id {mine}")
    # the folder's run on another address: refused unless the service there holds this very run
    elsewhere = "http://127.0.0.1:9"
    (run / "service_run.json").write_text(json.dumps({"api": elsewhere, "run_id": theirs}))
    proc = api_train(service, "--out", str(run), "--resume", "--epochs", "3", "--run-id", str(theirs))
    refused(proc, f"belongs to run {theirs} on {elsewhere}", f"run {theirs} on {service} is another run", "seed")
    (run / "service_run.json").write_text(json.dumps({"api": elsewhere, "run_id": mine}))  # moved: `collie up --port 0`
    proc = api_train(service, "--out", str(run), "--resume", "--epochs", "3", "--run-id", str(mine))
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_a_finished_run_resumed_on_the_service_trains_nothing_and_says_nothing_to_it(
    service: str, metra_run: Trained, tmp_path: Path
) -> None:
    """Was: "report status not delivered: 409: run N is finished" at every such start (compose's
    trainer, say, brought up again after its run ended)."""
    run = Path(shutil.copytree(metra_run.out, tmp_path / "run"))
    mine = json.loads((run / "service_run.json").read_text())["run_id"]
    proc = api_train(service, "--out", str(run), "--resume", "--epochs", "2", "--run-id", str(mine))
    assert proc.returncode == 0 and "nothing to train" in proc.stderr, proc.stderr[-3000:]
    assert "not delivered" not in proc.stderr and "warning" not in proc.stderr.lower(), proc.stderr[-3000:]


def test_a_service_run_json_without_a_run_id_is_named(run_copy: Path, service: str) -> None:
    """1e400 was an OverflowError traceback."""
    (run_copy / "service_run.json").write_text(f'{{"api": "{service}", "run_id": 1e400}}')
    proc = api_train(service, "--out", str(run_copy), "--resume", "--epochs", "3")
    refused(proc, str(run_copy / "service_run.json"), "damaged", "not a run id", "give the run's --run-id")


@pytest.mark.parametrize("run_id", ["1e400", "1.5", "true", "0", "-1", '"1"'])
def test_only_a_positive_integer_is_a_remembered_run_id(tmp_path: Path, run_id: str) -> None:
    """1.5 and true were read as run 1; 0 and -1 got the advice --run-id 0, which argparse refuses."""
    from trainer.cli import remembered_run

    memo = tmp_path / "service_run.json"
    memo.write_text(f'{{"api": "http://127.0.0.1:8000", "run_id": {run_id}}}')
    with pytest.raises(ValueError, match=f"{re.escape(str(memo))} is damaged .*is not a run id") as err:
        remembered_run(memo)
    assert "--run-id 0" not in str(err.value) and "--run-id -1" not in str(err.value)


def test_the_car_runs_its_own_task_by_default_and_a_plane_task_is_refused_naming_its_own(tmp_path: Path) -> None:
    refused(
        train("--env", "car", "--task", "north", "--out", str(tmp_path / "north")),
        "task 'north' is not defined for env 'car'",
        "car's tasks: hazard",
    )
    given_none = train("--env", "car", "--epochs", "1", "--out", str(tmp_path / "run"))
    assert given_none.returncode == 0, given_none.stderr[-3000:]
    assert json.loads((tmp_path / "run" / "config.json").read_text())["task"] == "hazard"


@pytest.mark.parametrize(
    ("flag", "value"),
    [
        ("--seed", "-1"),
        ("--run-id", "abc"),
        ("--episode-steps", "0"),
        ("--threads", "-2"),
        ("--threads", "100000"),  # was: OpenMP's "thread constructor failed", then a segfault (exit 139)
        ("--seed", "99999999999999999999"),  # was: "Overflow when unpacking long long"
        ("--hidden", "100000000"),  # was: an allocation traceback
        ("--batch-size", "99999999999999999999"),
    ],
)
def test_a_bad_value_names_its_flag(tmp_path: Path, flag: str, value: str) -> None:
    refused(train("--epochs", "1", "--out", str(tmp_path / "run"), flag, value, timeout=60), flag, value)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("name", ["config.json", "task.json"])
def test_a_damaged_run_file_is_named_on_resume(run_copy: Path, name: str) -> None:
    (run_copy / name).write_text('{"epochs": 3,')
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), str(run_copy / name))


def test_a_config_value_of_another_type_is_named_on_resume(run_copy: Path) -> None:
    """Was a TypeError traceback from deep in the trainer."""
    config = run_copy / "config.json"
    config.write_text(json.dumps(json.loads(config.read_text()) | {"hidden": "64"}))
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), str(config), repr("hidden"), '"64"')


@pytest.mark.parametrize(
    ("key", "value", "said"), [("env", "nope", "unknown env 'nope'"), ("hidden", 0, "must be ≥ 1")]
)
def test_a_bad_config_value_is_named_with_its_file_on_resume(
    run_copy: Path, key: str, value: object, said: str
) -> None:
    """Was "collie train: error: unknown env 'nope'", which reads as a typo on a command line that gave no --env."""
    config = run_copy / "config.json"
    config.write_text(json.dumps(json.loads(config.read_text()) | {key: value}))
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), f"{config}: ", said)


@pytest.mark.parametrize(
    ("key", "value", "kind"),
    [
        ("hidden", '"64"', "an integer"),
        ("hidden", "64.5", "an integer"),
        ("epochs", "null", "an integer"),
        ("fused_adam", "1", "true or false"),
        ("acting", '"fastest"', 'one of "fast", "torch"'),
        ("lr", "true", "a number"),
    ],
)
def test_a_stored_config_value_of_another_type_is_named(key: str, value: str, kind: str) -> None:
    from trainer.config import Config, make_config
    from trainer.run_files import RunFolderError

    stored = make_config("smoke", "point").to_dict() | {key: json.loads(value)}
    with pytest.raises(RunFolderError, match=re.escape(f"config.json: {key!r} must be {kind}, got {value}")):
        Config.from_stored(stored, "config.json")


def test_a_metrics_line_without_an_integer_epoch_is_named(run_copy: Path) -> None:
    metrics = run_copy / "metrics.jsonl"
    metrics.write_text('{"epoch": "3"}\n' + metrics.read_text())  # was a TypeError traceback ({"x": 1}: KeyError)
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), str(metrics), "line 1", "epoch")


@pytest.mark.parametrize("how", ["truncated", "slots beyond the replay"])
def test_a_damaged_replay_chunk_is_named(run_copy: Path, how: str) -> None:
    chunk = sorted((run_copy / "replay").glob("*.npz"))[-1]
    if how == "truncated":  # was zipfile.BadZipFile
        chunk.write_bytes(chunk.read_bytes()[:300])
    else:  # was an IndexError
        with np.load(chunk) as data:
            arrays = dict(data)
        arrays["slots"] = arrays["slots"] + 10_000
        with open(chunk, "wb") as f:
            np.savez(f, **arrays)
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), str(chunk), "damaged")


@pytest.fixture(scope="module")
def seed_one(tmp_path_factory: pytest.TempPathFactory) -> Trained:
    """A fresh 1-epoch run like `finished` but of seed 1, given more threads than this machine has
    cores (a runtime setting, no part of what makes the run: trainer/same_run.py)."""
    out = tmp_path_factory.mktemp("seed_one") / "run"
    proc = train("--epochs", "1", "--out", str(out), "--seed", "1", "--threads", str((os.cpu_count() or 1) + 1))
    assert proc.returncode == 0, proc.stderr[-3000:]
    return Trained(out, proc)


def test_a_checkpoint_of_another_run_of_the_same_shapes_is_refused(run_copy: Path, seed_one: Trained) -> None:
    """Was resumed silently: the other seed's networks and replay continued under this run's name."""
    shutil.copyfile(seed_one.out / "checkpoint.pt", run_copy / "checkpoint.pt")
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), "copied from another run", "seed (1 there")


def test_resume_warns_about_the_flags_it_ignores_and_what_a_run_saved_before_some_options_assumed(
    run_copy: Path,
) -> None:
    """--resume keeps the run's config: one warning names the flags it ignores. A run saved by an
    older collie lacks the keys of options added since: it resumes with what it ran with
    (FIRST_VERSION), and says so once, as config.json is rewritten with them."""
    saved = json.loads((run_copy / "config.json").read_text())
    for key in ("fused_adam", "fast_ops", "flush_denormal"):
        del saved[key]
    (run_copy / "config.json").write_text(json.dumps(saved))
    # TRAIN gives --env point and --preset smoke again (as `collie up` and `collie sweep` do): not warned
    proc = train(
        "--out", str(run_copy), "--resume", "--epochs", "3", "--env", "ant", "--method", "metra", "--hidden", "64",
        "--threads", "2",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    warnings = [ln for ln in proc.stderr.splitlines() if ln.startswith("collie train: warning:")]
    assert len(warnings) == 1, proc.stderr[-3000:]
    assert "--env ant (the run's: point)" in warnings[0] and "--method metra (the run's: collie)" in warnings[0]
    assert "--epochs" not in warnings[0] and "--hidden" not in warnings[0] and "--preset" not in warnings[0]
    assert json.loads((run_copy / "summary.json").read_text())["config"]["env"] == "point"
    assert "--threads" not in warnings[0]  # a runtime setting: the resumed run uses what it is given
    assert json.loads((run_copy / "config.json").read_text())["threads"] == 2
    said = f"collie train: {run_copy / 'config.json'} predates some options; it resumes as it ran: "
    assert said + "--fused-adam false, --fast-ops false, --flush-denormal false" in proc.stderr, proc.stderr[-2000:]
    assert json.loads((run_copy / "config.json").read_text())["fused_adam"] is False
    events = sorted((run_copy / "tb").iterdir())
    wall_s = json.loads((run_copy / "summary.json").read_text())["wall_s"]
    fewer = train("--out", str(run_copy), "--resume", "--epochs", "1")  # epochs may only be extended
    assert sorted((run_copy / "tb").iterdir()) == events  # nothing trained: no empty event file added
    assert json.loads((run_copy / "summary.json").read_text())["wall_s"] == wall_s  # nor time (was: + the start's)
    said = "ignored: --epochs 1 (the run's: 3; epochs may only be extended)"  # was: as if any value were refused
    assert fewer.returncode == 0 and said in fewer.stderr, fewer.stderr[-3000:]
    assert "finished all its 3 epochs: nothing to train (--epochs above 3 extends it)" in fewer.stderr
    assert "predates" not in fewer.stderr  # said once: the keys are written now


def test_a_run_started_on_a_gpu_resumes_on_a_machine_without_one_with_device_cpu(run_copy: Path) -> None:
    """Was: the run's own --device cuda won on resume, so a run moved off a GPU machine could never
    resume (--device cpu was "ignored"). --device is taken as given; fast ops are chosen again for
    another kind of device, and kept for the same kind or "auto" (a resume stays exact)."""
    no_gpu = {**os.environ, "CUDA_VISIBLE_DEVICES": ""}  # a machine without one, whatever this one has
    saved = json.loads((run_copy / "config.json").read_text())
    gpus = not fast_ops_pay(torch.device("cpu"))  # the run's, unlike this CPU's choice
    (run_copy / "config.json").write_text(json.dumps({**saved, "device": "cuda", "fast_ops": gpus}))
    said = refused(train("--out", str(run_copy), "--resume", "--epochs", "3", env=no_gpu), "use --device cpu")
    assert f"(cuda is the run's own, from {run_copy / 'config.json'}; --resume with another --device" in said
    proc = train("--out", str(run_copy), "--resume", "--epochs", "3", "--device", "cpu", env=no_gpu)
    assert proc.returncode == 0 and "warning" not in proc.stderr, proc.stderr[-3000:]
    config = json.loads((run_copy / "config.json").read_text())
    assert config["device"] == "cpu" and config["fast_ops"] == (not gpus)  # chosen again, for the CPU
    assert json.loads((run_copy / "summary.json").read_text())["epochs_done"] == 3
    proc = train("--out", str(run_copy), "--resume", "--epochs", "4", "--device", "auto", env=no_gpu)
    assert proc.returncode == 0 and "warning" not in proc.stderr, proc.stderr[-3000:]
    config = json.loads((run_copy / "config.json").read_text())
    assert config["device"] == "auto" and config["fast_ops"] == (not gpus)  # "auto": no other kind named, kept


def test_the_line_printed_after_ctrl_c_agrees_with_summary_json(tmp_path: Path) -> None:
    out = tmp_path / "run"
    # one evaluation (epoch 0) and then none: the interrupted run's last one lies behind it
    cmd = [*TRAIN, "--out", str(out), "--epochs", "1000", "--eval-every", "1000"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not (out / "checkpoint.pt").exists():  # a few epochs past the evaluation
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()[1][-3000:]
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr[-3000:]  # docs/training.md: a checkpointed interruption exits 0
    printed, summary = json.loads(stdout.splitlines()[0]), json.loads((out / "summary.json").read_text())
    assert summary["status"] == printed["status"] == "interrupted"
    assert printed["epochs_done"] == summary["epochs_done"] >= 2 and printed["epoch"] == summary["epoch"] == 0
    evaluated = json.loads((out / "metrics.jsonl").read_text().splitlines()[-1])
    assert printed["wall_s"] == summary["wall_s"] > evaluated["wall_s"]
    said = f"stopped after epoch {summary['epochs_done']} of 1000; `collie train --out {out} --resume` continues"
    assert stderr.strip().splitlines()[-1] == f"collie train: {said}"  # where it stopped, not the evaluation's epoch
    # said when the signal came (was: nothing until the epoch ended, minutes on a pixel robot)
    heard = f"collie train: SIGINT: stopping at the end of epoch {summary['epochs_done']}, with a checkpoint; again to"
    assert f"{heard} stop at once, without one" in stderr.splitlines(), stderr[-3000:]


def test_help_lists_every_registered_task() -> None:
    from collie.tasks import task_names

    proc = subprocess.run([*TRAIN, "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    flat = " ".join(proc.stdout.split())
    assert "hazard" in task_names() and all(name in flat for name in task_names())
    assert "--hidden HIDDEN width of every MLP layer" in flat  # each hyperparameter says what it is
    assert "car (default point)" in flat and "(default collie)" in flat and "the run's seed (default 0)" in flat


def test_print_config_shows_what_the_flags_make_and_starts_nothing(tmp_path: Path) -> None:
    from trainer.config import make_config

    out = tmp_path / "never"
    proc = subprocess.run(
        [*TRAIN[:4], "--env", "ant", "--preset", "cpu", "--lr", "3e-4", "--print-config", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    shown = json.loads(proc.stdout)
    assert shown == {**make_config("cpu", "ant", lr=3e-4, out=str(out)).to_dict(), "fast_ops": None}
    assert not out.exists()
    refused(train("--out", str(out), "--resume", "--print-config"), "--print-config shows what flags make")
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\ndescription = "x"\n[[regions]]\nkind = "moat"\n')
    refused(train("--task-file", str(bad), "--print-config"), f"task file {bad}")  # as a run would refuse it
    for flags, said in (  # was: refused only once a run had built its env and nets
        (["--method", "lsd"], "LSD's Lipschitz φ reads state vectors, and quadruped observes 64×64 pixels"),
        (["--distance", "l2"], "--distance l2 (LSD's Lipschitz φ) reads state vectors, and quadruped observes"),
        (["--method", "dodont", "--instruction", "x"], "dodont's instruction classifier (an MLP) reads state"),
        (["--method", "ddg", "--instruction", "x"], "ddg's instruction classifier (an MLP) reads state vectors"),
    ):
        refused(train("--env", "quadruped", *flags, "--print-config"), said)
    refused(train("--method", "ddg", "--instruction", "x", "--distance", "l2", "--print-config"), "ddg runs on")
    with open("/dev/full", "w") as full:  # was "cannot start the run in runs/…: no space left on device"
        proc = subprocess.run([*TRAIN, "--print-config"], stdout=full, stderr=subprocess.PIPE, text=True, timeout=60)
    refused(proc, "--print-config: cannot write to standard output: No space left on device")


def test_the_end_of_run_line_lists_only_what_was_written(metra_run: Trained) -> None:
    out, proc = metra_run.out, metra_run.proc  # METRA: no guidance, no w(s) map
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = proc.stdout.strip().splitlines()[-1]
    assert line.startswith(f"run folder: {out}") and "summary.json" in line and "checkpoint.pt" in line
    assert not (out / "guidance_latest.png").exists() and "guidance_latest.png" not in line


def test_a_run_labelled_through_the_service_is_not_resumed_with_the_oracle(run_copy: Path) -> None:
    """A `collie up` trainer folder (service_run.json) resumed without --api would mix the scripted
    oracle's labels into a run people label: refused, saying what to give."""
    (run_copy / "service_run.json").write_text(json.dumps({"run_id": 1}))
    before = digest(run_copy / "checkpoint.pt")
    refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), "--api", "service_run.json")
    assert digest(run_copy / "checkpoint.pt") == before


def test_a_second_trainer_in_a_run_folder_in_use_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "run"
    first = subprocess.Popen(
        [*TRAIN, "--out", str(out), "--epochs", "100000", "--checkpoint-every", "100000"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 120
        while not (out / "metrics.jsonl").exists():
            assert first.poll() is None and time.monotonic() < deadline
            time.sleep(0.1)
        refused(train("--out", str(out)), f"another collie train (pid {first.pid}) is training in {out}")
        # before its first checkpoint, a --resume is told the same (was: "no checkpoint: nothing to resume")
        said = f"another collie train (pid {first.pid}) is training in {out}, and has written no checkpoint yet"
        refused(train("--out", str(out), "--resume"), said)
        assert first.poll() is None  # the first goes on
    finally:
        first.kill()
        first.wait()
    assert train("--out", str(out), "--epochs", "1").returncode == 0  # its lock ends with it


def test_a_checkpoint_from_another_run_is_named_on_resume(run_copy: Path, metra_run: Trained) -> None:
    """Another method's checkpoint (METRA's networks, not COLLIE's) in this run's folder."""
    shutil.copyfile(metra_run.out / "checkpoint.pt", run_copy / "checkpoint.pt")
    refused(
        train("--out", str(run_copy), "--resume"),
        f"{run_copy / 'checkpoint.pt'} does not fit this run's config.json (copied from another run?)",
    )


@pytest.mark.parametrize("at", ["python start", "imports"])  # torch's import next (was: exit 143, no word); envs next
@pytest.mark.parametrize(
    "sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"]
)  # SIGINT in the imports was a traceback, or exit 1
def test_a_signal_while_the_trainer_starts_ends_it_as_ctrl_c_does(tmp_path: Path, at: str, sig: int) -> None:
    marks = PacedMarks(tmp_path)  # the signal lands before the trainer's next mark
    cmd = [*TRAIN, "--out", str(tmp_path / "run"), "--epochs", "1"]
    code, err = marks.run(cmd, lambda m: m.what == at, sig)
    assert code == 130 and "collie train: interrupted" in err and "Traceback" not in err, err[-3000:]
    assert not (tmp_path / "run" / "summary.json").exists()  # it ended before training, not after


def test_an_abbreviated_flag_is_not_taken_for_the_flag(tmp_path: Path) -> None:
    """`--ou X` would be `--out X` to argparse by default: then `collie up --train-args` and `collie
    sweep -- …`, which refuse the flags they set themselves, would have to know every prefix."""
    proc = train("--epochs", "1", "--ou", str(tmp_path / "run"), timeout=60)
    last = proc.stderr.strip().splitlines()[-1]  # the command named: `collie up --train-args` quotes it (was "collie:")
    assert proc.returncode == 2 and last.startswith("collie train: error: unrecognized arguments: --ou"), last
    assert not (tmp_path / "run").exists()


def evaluation_next(mark: StartupMark) -> bool:
    """The mark after which the trainer runs its epoch-0 evaluation."""
    return mark.what == "run files, tensorboard"


def test_sigterm_after_the_start_before_the_first_epoch_stops_the_run_checkpointed(tmp_path: Path) -> None:
    """Between the start's check and the loop's own handler (the run's files, its epoch-0
    evaluation) a SIGTERM was noted and then ignored: `collie up` waited 15 s and killed it."""
    marks = PacedMarks(tmp_path)
    out = tmp_path / "run"
    code, err = marks.run([*TRAIN, "--out", str(out), "--epochs", "3"], evaluation_next, signal.SIGTERM)
    assert code == 0, err[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["status"], summary["epochs_done"]) == ("interrupted", 0) and (out / "checkpoint.pt").exists()


@pytest.mark.parametrize("folder", ["new", "holding a file"])
def test_ctrl_c_in_the_epoch_0_evaluation_leaves_no_run_behind(tmp_path: Path, folder: str) -> None:
    """Was: exit 130 and a folder of config.json, metrics.jsonl, tb/ and train.lock that --resume
    refused (no checkpoint). What the folder held before the start stays."""
    marks = PacedMarks(tmp_path)
    out = tmp_path / "run"
    if folder != "new":
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    code, err = marks.run([*TRAIN, "--out", str(out), "--epochs", "3"], evaluation_next, signal.SIGINT)
    assert code == 130 and "collie train: interrupted" in err and "Traceback" not in err, err[-3000:]
    if folder == "new":
        assert not out.exists()
        assert f"collie train: stopped before its first checkpoint: removed {out}, which it made" in err
    else:
        assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
        assert f"collie train: stopped before its first checkpoint: removed what it wrote in {out}" in err


def test_a_second_ctrl_c_says_which_checkpoint_a_resume_continues_from(tmp_path: Path) -> None:
    """Was: "collie train: interrupted" alone, the epoch a resume goes back to unsaid."""
    out = tmp_path / "run"
    cmd = [*TRAIN, "--out", str(out), "--epochs", "1000", "--eval-every", "1000", "--grad-steps", "3000"]
    proc = subprocess.Popen([*cmd, "--checkpoint-every", "1"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not (out / "checkpoint.pt").exists():
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.3)
    proc.send_signal(signal.SIGINT)  # within the same epoch: an epoch of 3000 steps takes seconds
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-3000:]
    said = re.search(
        r"collie train: stopped in epoch (\d+) without a checkpoint of it: --resume continues from epoch (\d+)'s", err
    )
    assert said is not None, err[-3000:]
    assert int(said[2]) == int(said[1]) - 1 and (out / "checkpoint.pt").exists()


def test_sigterm_while_waiting_for_the_service_ends_it_at_once(tmp_path: Path) -> None:
    """Was noted and ignored: the wait went on its 120 s (docker stop and systemd then SIGKILL)."""
    cmd = [*TRAIN, "--out", str(tmp_path / "run"), "--api", "http://127.0.0.1:9", "--token", TOKENS["trainer"]]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr is not None
        for line in proc.stderr:
            if "waiting for the labeling service at http://127.0.0.1:9 (at most 120 s)" in line:  # says how long
                break
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        err = proc.stderr.read()
        proc.wait(timeout=60)
    finally:
        proc.kill()
    assert time.monotonic() - sent < 30, err  # the wait it cut short is 120 s
    assert proc.returncode == 130 and "collie train: interrupted" in err and "Traceback" not in err, err
    assert not (tmp_path / "run").exists()  # was left holding only train.lock


def test_a_task_file_that_exits_is_one_line_and_leaves_no_run_folder(tmp_path: Path) -> None:
    """Was: exit 3 without a word, and a new run folder holding only train.lock."""
    quits = tmp_path / "quits.py"
    quits.write_text("import sys\n\nsys.exit(3)\n")
    refused(train("--task-file", str(quits), "--out", str(tmp_path / "new" / "run")), "exit status 3", str(quits))
    assert not (tmp_path / "new").exists()


def test_a_wrong_token_for_an_existing_run_is_one_line(service: str, metra_run: Trained, tmp_path: Path) -> None:
    """Was a SourceRefused traceback, exit 1: held_run()'s refusal escaped the start's ApiError check."""
    mine = json.loads((metra_run.out / "service_run.json").read_text())["run_id"]
    run = Path(shutil.copytree(metra_run.out, tmp_path / "run"))
    before = digest(run / "checkpoint.pt")
    wrong = ("--api", service, "--token", "wrong-" + "x" * 30)
    words = (f"refused the trainer's token for run {mine}", "401: unknown or revoked token", service)
    refused(train("--method", "metra", *wrong, "--out", str(run), "--resume", "--epochs", "3"), *words)
    assert digest(run / "checkpoint.pt") == before
    refused(train("--method", "metra", *wrong, "--out", str(tmp_path / "new"), "--run-id", str(mine)), *words)
    assert not (tmp_path / "new").exists()


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_disk_during_the_run_is_one_line_and_the_run_resumes(run_copy: Path) -> None:
    """Was an OSError traceback (No space left on device), exit 1. /dev/full fails every write with
    ENOSPC, as a full disk does."""
    before = digest(run_copy / "checkpoint.pt")
    (run_copy / "skills_latest.png").unlink()
    (run_copy / "skills_latest.png").symlink_to("/dev/full")
    line = refused(train("--out", str(run_copy), "--resume", "--epochs", "3"), "the disk is full", str(run_copy))
    assert line.endswith("continue it with --resume once there is space"), line
    (run_copy / "skills_latest.png").unlink()  # space again: it goes on from the kept checkpoint
    assert digest(run_copy / "checkpoint.pt") == before
    proc = train("--out", str(run_copy), "--resume", "--epochs", "3")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert json.loads((run_copy / "summary.json").read_text())["epochs_done"] == 3


@pytest.mark.parametrize("how", ["full", "read-only"])
def test_a_new_run_on_a_full_or_read_only_disk_is_one_line_naming_its_folder(tmp_path: Path, how: str) -> None:
    """Was: a full disk's "cannot write: No space left on device", naming nothing, and OUT/train.lock
    left behind (its pid was the write refused); a read-only one said "permission denied"."""
    with small_disk(tmp_path / "disk", read_only=how == "read-only") as disk:
        if how == "full":
            fill(disk)
        run = disk / "new"
        said = (
            f"cannot start the run in {run}: no space left on device"
            if how == "full"
            else f"--out {run}: cannot write in {disk} (read-only file system)"
        )
        line = refused(train("--epochs", "1", "--out", str(run)), said)
        assert line == f"collie train: error: {said}"
        assert not run.exists()


def test_a_file_system_turned_read_only_is_named(tmp_path: Path) -> None:
    from trainer.cli import write_failure

    (tmp_path / "checkpoint.pt").write_bytes(b"")
    said = write_failure(OSError(errno.EROFS, os.strerror(errno.EROFS), str(tmp_path / "m")), tmp_path)
    assert said == (
        f"the run stopped: the file system is read-only now (read-only file system) writing {tmp_path / 'm'}: "
        "continue it with --resume once it is writable"
    )
    said = write_failure(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)), tmp_path / "new")
    assert said.endswith(f"writing {tmp_path / 'new'}: start it again once there is space"), said


def test_more_threads_than_cores_is_a_warning(seed_one: Trained) -> None:
    more, proc = (os.cpu_count() or 1) + 1, seed_one.proc  # a 1-epoch run given --threads {more}
    assert proc.returncode == 0, proc.stderr[-3000:]
    said = f"collie train: warning: --threads {more} is more than this machine's {more - 1} cores"
    assert said in proc.stderr, proc.stderr[-3000:]


def at_most_16_gib() -> None:
    """The child's address space: an allocation beyond it fails on any machine, however large."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (16 << 30, 16 << 30))


@pytest.mark.parametrize("flag", ["--replay-capacity", "--eval-trajectories"])
def test_sizes_beyond_memory_are_one_line_naming_the_flag(tmp_path: Path, flag: str) -> None:
    """Were numpy's _ArrayMemoryError and MuJoCo's "Could not allocate memory" tracebacks, and a run
    folder left holding only train.lock. (The replay's arrays still fail in numpy under the limit:
    the memory plan counts only what a 1-epoch run fills. The envs are refused by the plan now.)"""
    cmd = [*TRAIN, "--device", "cpu", "--epochs", "1", "--out", str(tmp_path / "run"), flag, "2000000000"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, preexec_fn=at_most_16_gib)
    refused(proc, "not enough memory", f"{flag} 2000000000")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("sizes", "said"),
    [
        # more than any machine has free (≈ 13 TiB, ≈ 11 PiB); 100000 envs were minutes of envs, then exit 137
        (["--eval-trajectories", "10000000"], "(10000000 point envs: at least"),
        (["--replay-capacity", "2000000000", "--batch-size", "2000000000"], "(the networks, a gradient step and"),
        (["--hidden", "65536"], "(the networks, a gradient step and"),  # was 54 s, 17 GB, then torch's traceback
    ],
)
def test_sizes_beyond_free_memory_are_refused_before_they_are_taken(tmp_path: Path, sizes, said: str) -> None:
    """Sizes each allocation of which Linux lends at once: the pages are taken as the run touches
    them, until the kernel kills it without a word. (The address-space limit only keeps a failure of
    this test from taking the machine's memory.)"""
    cmd = [*TRAIN, "--device", "cpu", "--epochs", "1", "--out", str(tmp_path / "run"), *sizes]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, preexec_fn=at_most_16_gib)
    line = refused(proc, "not enough memory", " ".join(sizes[:2]), said, "GiB free): give smaller ones")
    assert float(line.split("at least ")[1].split(" GiB")[0]) > 16  # a lower bound, and still more than the limit
    assert not (tmp_path / "run").exists()


def test_two_runs_side_by_side_do_not_both_count_the_same_free_memory(tmp_path: Path) -> None:
    """Each run's replay fits the memory free now, not both: the first is promised its part (Linux
    would lend it page by page, and the kernel kill one of the runs hours later), the second is
    refused with exit 75 naming the first; once the first has ended, the second starts."""
    from trainer.config import make_config
    from trainer.envs.registry import make_env
    from trainer.memory_plan import available_bytes, replay_fill_bytes

    cfg, env = make_config("smoke", "point"), make_env("point")
    free = available_bytes()
    assert free is not None
    each = replay_fill_bytes(
        1, cfg.episode_steps, env.obs_shape, np.dtype(env.obs_dtype), env.action_dim, env.nq, env.nv
    )
    held = int(0.55 * free / each)  # trajectories: the replay's arrays are made as large (numpy refuses more)
    epochs = held // cfg.episodes_per_epoch + 1  # and the run would fill them
    sizes = ["--epochs", str(epochs), "--replay-capacity", str(held * cfg.episode_steps)]
    ledger = {**os.environ, "COLLIE_MEMORY_LEDGER": str(tmp_path / "ledger")}

    def start(name: str) -> subprocess.Popen[bytes]:
        cmd = [*TRAIN, *sizes, "--out", str(tmp_path / name)]
        with open(tmp_path / f"{name}.log", "ab") as log:
            return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=ledger)

    def promised(proc: subprocess.Popen[bytes], name: str) -> None:
        deadline = time.monotonic() + 120
        while not (tmp_path / "ledger" / f"{proc.pid}.json").exists():
            assert proc.poll() is None, (tmp_path / f"{name}.log").read_text()[-3000:]
            assert time.monotonic() < deadline, f"no promise in the ledger from the {name} run"
            time.sleep(0.1)

    first = start("first")
    try:
        promised(first, "first")
        second = subprocess.run(
            [*TRAIN, *sizes, "--out", str(tmp_path / "second")], capture_output=True, text=True, env=ledger, timeout=120
        )
        assert second.returncode == os.EX_TEMPFAIL, second.stderr[-3000:]
        line = second.stderr.strip().splitlines()[-1]
        assert line.startswith("collie train: error: this machine has not enough memory for the run's sizes"), line
        assert f"GiB of it promised to running runs (pid {first.pid})" in line
        assert line.endswith(": give smaller ones, or start it once those runs have ended"), line
        assert not (tmp_path / "second").exists()
    finally:
        first.kill()
        first.wait()
    again = start("second")  # the first's promise went with its process (killed: no word of its end)
    try:
        promised(again, "second")
    finally:
        again.kill()
        again.wait()


HUGE_MODEL = (  # an arena of 4 PB
    '<mujoco><size memory="4000000G"/><worldbody><body><freejoint/><geom size="1"/></body></worldbody></mujoco>'
)


@pytest.mark.parametrize(
    "allocate",
    [
        lambda: np.empty(2**62, np.uint8),  # numpy: MemoryError
        lambda: mujoco.MjModel.from_xml_string(HUGE_MODEL),  # MuJoCo: "engine error: Could not allocate memory"
        lambda: torch.empty(2**62, dtype=torch.uint8),  # torch on the CPU: a RuntimeError (was a traceback)
    ],
    ids=["numpy", "mujoco", "torch"],
)
def test_each_library_s_failed_allocation_is_said_as_short_of_memory(allocate) -> None:
    """What the memory plan did not foresee (e.g. a batch in the run) fails in numpy, MuJoCo or
    torch, each in its own way; all are the one line. (torch.OutOfMemoryError on a GPU says "CUDA
    out of memory", matched the same way.)"""
    with pytest.raises(Exception) as failed:  # each beyond any address space: refused at once
        allocate()
    args = argparse.Namespace(given={"batch_size"}, batch_size=4096, resume=False, preset="cpu")
    line = short_of_memory(failed.value, args)
    assert line == "this machine has not enough memory for the run's sizes (--batch-size 4096): give smaller ones"
    assert short_of_memory(RuntimeError("mat1 and mat2 shapes cannot be multiplied"), args) is None


@pytest.mark.parametrize("answer", ["none", "a page"])
def test_a_service_gone_or_not_itself_while_the_run_is_created_is_one_line(tmp_path: Path, answer: str) -> None:
    """The service answers its health check, then drops the request that creates the run (which is
    not sent twice: it might make two runs), or answers it with a proxy's page. Was: the client's
    Unreachable as a traceback; now one line naming the service, and exit 1 (transient: `collie up`
    restarts the trainer); a page: exit 2, said once (was: "answered POST … answered 200 …")."""
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
    from threading import Thread

    from collie.schemas import Health

    class HealthyThenGone(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = Health(status="ok", version="0", database="sqlite").model_dump_json().encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def do_POST(self) -> None:
            self.close_connection = True  # no answer at all: the connection closes
            if answer == "a page":
                page = b"<html><title>Sign in to the proxy</title></html>"
                self.send_response(200)
                self.send_header("Content-Type", "text/html")
                self.send_header("Content-Length", str(len(page)))
                self.end_headers()
                self.wfile.write(page)

        def log_message(self, *_: object) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), HealthyThenGone)
    Thread(target=server.serve_forever, daemon=True).start()
    api = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        proc = train("--out", str(tmp_path / "run"), "--api", api, env={**os.environ, "COLLIE_TOKEN": "tr-" + "t" * 30})
    finally:
        server.shutdown()
        server.server_close()
    assert proc.returncode == (1 if answer == "none" else 2), proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith(f"collie train: error: the labeling service at {api} "), line
    assert answer == "none" or ("Sign in to the proxy" in line and line.count("answered") == 1), line


def test_the_paper_preset_on_pixels_without_a_gpu_is_warned_of(tmp_path: Path) -> None:
    """Was unsaid: an epoch of it takes many minutes on a CPU (docs/envs.md)."""
    cmd = [*TRAIN[:4], "--env", "quadruped", "--preset", "paper", "--no-progress", "--out", str(tmp_path / "run")]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, env={**os.environ, "CUDA_VISIBLE_DEVICES": ""})
    said = "collie train: warning: the paper preset on quadruped's pixels is sized for a GPU: on this CPU each of "
    deadline = threading.Timer(120, proc.kill)  # it would train for hours: never wait for its end
    deadline.start()
    try:
        assert proc.stderr is not None
        for line in proc.stderr:  # said before the run is built
            if line.startswith(said):
                assert "updates takes seconds (docs/envs.md); --preset cpu tries the loop out" in line
                break
        else:
            pytest.fail("no warning before collie train ended (or 120 s passed)")
    finally:
        deadline.cancel()
        proc.kill()
        proc.wait()
