"""kill -9 of a trainer while it waits for labels, then a restart: it resumes from its checkpoint,
rebuilds D0/D1/D2 from the service, and finishes — no label lost, none applied twice."""

import contextlib
import json
import os
import re
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
from stalling_proxy import stalling_relay

from collie.client import CollieClient
from collie.schemas import EnvDims, QueriesEvent, RunCreate, StatusEvent
from collie.tasks import get_task
from collie.teacher import OracleTeacher

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)

TOKENS = {"operator": "op-" + "o" * 30, "trainer": "tr-" + "t" * 30, "labeler": "lb-" + "l" * 30}


def cli(*args: str, log: Path) -> subprocess.Popen:
    env = {**os.environ, **{f"COLLIE_{k.upper()}_TOKEN": v for k, v in TOKENS.items()}}
    return subprocess.Popen(
        [sys.executable, "-m", "collie.cli", *args], stdout=open(log, "ab"), stderr=subprocess.STDOUT, env=env
    )


def wait_until(pred, timeout_s: float = 180.0, alive: subprocess.Popen | None = None, log: Path | None = None) -> None:
    """`pred()` within timeout_s; with `alive`, fail at once (its log's end) when that process ends first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return
        if alive is not None and alive.poll() is not None:
            said = log.read_text()[-3000:] if log is not None and log.exists() else ""
            raise AssertionError(f"it exited with {alive.returncode} first:\n{said}")
        time.sleep(0.2)
    raise TimeoutError("condition not reached")


NORTH_ORACLE = OracleTeacher(get_task("north", "point"))  # the rule of `collie train`'s default task


def train_args(out: Path, api: str, *more: str) -> list[str]:
    """`collie train` of a smoke run labelled through the service at `api`."""
    return ["train", "--preset", "smoke", "--out", str(out), "--api", api, "--no-progress", *more]


@contextlib.contextmanager
def running_service(tmp_path: Path) -> Iterator[str]:
    """`collie serve` on a SQLite file in tmp_path; yields its URL, stops it after."""
    info = tmp_path / "service.json"
    service = cli(
        "serve", "--port", "0", "--db", str(tmp_path / "c.db"), "--tokens-json", str(info), log=tmp_path / "service.log"
    )
    try:
        wait_until(info.exists)
        yield json.loads(info.read_text())["api"]
    finally:
        service.terminate()
        service.wait(timeout=30)


@dataclass(frozen=True)
class Service:
    api: str
    db: Path  # its SQLite file


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    """One service for the file's tests (each makes its own runs): a start and a stop per test cost
    ≈2 s of the worker's time."""
    tmp = tmp_path_factory.mktemp("service")
    with running_service(tmp) as api:
        yield Service(api, tmp / "c.db")


@dataclass(frozen=True)
class Finished:
    out: Path
    run_id: int


@pytest.fixture(scope="module")
def unanswered(service: Service, tmp_path_factory: pytest.TempPathFactory) -> Finished:
    """A smoke run nobody labels, finished on the service (a --feedback-timeout lets it go on):
    test_sessions_nobody_answers_in_time_still_spend_the_budget checks what it asked, and
    test_a_trainer_unlike_the_run_it_is_given_is_refused_naming_the_differences offers it to trainers
    it is not; neither changes it."""
    tmp = tmp_path_factory.mktemp("unanswered")
    out, log = tmp / "trainer", tmp / "trainer.log"
    trainer = cli(*train_args(out, service.api, "--feedback-timeout", "0.5", "--epochs", "12"), log=log)
    assert trainer.wait(timeout=300) == 0, log.read_text()[-3000:]
    return Finished(out, json.loads((out / "service_run.json").read_text())["run_id"])


def waits_and_sessions(client: CollieClient, run_id: int) -> tuple[list[int], dict[int, int]]:
    """The epochs at which the trainer reported waiting for labels, and each session's epoch."""
    waits, sessions, after = [], {}, 0
    while page := client.events(run_id, after=after).events:
        for e in page:
            if isinstance(e, StatusEvent) and e.data.status == "waiting_for_labels":
                waits.append(e.data.epoch)
            elif isinstance(e, QueriesEvent):
                sessions[e.data.session] = e.data.epoch
        after = page[-1].id
    return waits, sessions


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_a_trainer_stopped_while_waiting_for_labels_resumes_in_that_wait(tmp_path, service, sig):
    """kill -9 resumes from the last periodic checkpoint (the epoch before), SIGTERM from its final
    one, written in the wait: either way the session is asked again at its own epoch, never later."""
    api = service.api
    out = tmp_path / "trainer"
    train = train_args(out, api, "--token", TOKENS["trainer"], "--checkpoint-every", "1")
    trainer = cli(*train, log=tmp_path / "trainer.log")
    memo = out / "service_run.json"
    wait_until(memo.exists, alive=trainer, log=tmp_path / "trainer.log")
    run_id = json.loads(memo.read_text())["run_id"]
    with CollieClient(api, TOKENS["operator"]) as client:
        wait_until(lambda: client.run(run_id).status == "waiting_for_labels")
        stopped_at = client.run(run_id).epoch
        trainer.send_signal(sig)
        assert trainer.wait(timeout=60) == (0 if sig == signal.SIGTERM else -signal.SIGKILL)
        if sig == signal.SIGTERM:  # the final checkpoint holds the session it waited on
            ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
            assert ckpt["epoch"] == stopped_at and [s.query_id for s in ckpt["asking"]] == ["s0-q0", "s0-q1"]
            # the line it ends with names the command that resumes it: with --api (refused without it)
            again = f"`collie train --out {out} --resume --api {api}` with the trainer's token continues"
            assert again in (tmp_path / "trainer.log").read_text()
        teacher = cli(
            "teacher",
            "--api",
            api,
            "--token",
            TOKENS["labeler"],
            "--run",
            str(run_id),
            "--until-done",
            log=tmp_path / "teacher.log",
        )
        restarted = cli(*train, "--resume", log=tmp_path / "trainer.log")
        assert restarted.wait(timeout=300) == 0, (tmp_path / "trainer.log").read_text()[-3000:]
        teacher.wait(timeout=60)
        in_db = {e.query_id: e.label for e in client.effective_labels(run_id)}
        waits, sessions = waits_and_sessions(client, run_id)
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    applied = {qid: seg["label"] for qid, seg in ckpt["labelled"].items()}
    assert applied == in_db and len(applied) == ckpt["config"]["total_queries"]
    assert ckpt["epoch"] == ckpt["config"]["epochs"] and ckpt["asking"] is None
    assert set(waits) == set(sessions.values()), f"waited at epochs {waits}; sessions asked at {sessions}"


def test_kill_9_after_an_answered_session_then_restart_asks_nothing_twice(tmp_path, service):
    """No checkpoint since the start (as after a crash): the restarted trainer replays from epoch 0,
    reaches the sessions it posted before and gets them back — one session per position, the label
    given before the kill applied, the budget not spent twice."""
    api = service.api
    out = tmp_path / "trainer"
    train = train_args(out, api)
    trainer = cli(*train, "--checkpoint-every", "100", log=tmp_path / "trainer.log")
    memo = out / "service_run.json"
    wait_until(memo.exists, alive=trainer, log=tmp_path / "trainer.log")
    run_id = json.loads(memo.read_text())["run_id"]
    with CollieClient(api, TOKENS["labeler"]) as labeler:

        def label_one_of(session: int) -> tuple[str, int]:
            """Labels a segment of `session` against the oracle's answer (north: bad ↔ neutral),
            so that the teacher's labels after the restart cannot pass for this one."""
            wait_until(lambda: any(q.session == session for q in labeler.queries(run_id, status="pending")))
            claim = labeler.claim(run_id)
            assert claim is not None and claim.query.session == session
            value = 1 - int(NORTH_ORACLE.label(np.asarray(claim.query.xy)))
            labeler.submit(run_id, claim.query.query_id, value)  # type: ignore[arg-type]
            return claim.query.query_id, value

        label_one_of(0), label_one_of(0)
        given, value = label_one_of(1)  # session 1: one label of two, then the crash
        trainer.send_signal(signal.SIGKILL)
        trainer.wait()
        assert not (out / "checkpoint.pt").exists()
        runs = {r.id for r in labeler.runs()}  # the file's other tests' runs too
        fresh = cli(*train, log=tmp_path / "fresh.log")  # a new run would orphan this one: refused
        assert fresh.wait(timeout=120) == 2
        said = (tmp_path / "fresh.log").read_text()
        assert f"belongs to run {run_id} of the service but holds no checkpoint: give --run-id {run_id}" in said
        assert {r.id for r in labeler.runs()} == runs  # it made none
        teacher = cli("teacher", "--api", api, "--run", str(run_id), "--until-done", log=tmp_path / "teacher.log")
        restarted = cli(*train, "--run-id", str(run_id), log=tmp_path / "trainer.log")
        assert restarted.wait(timeout=300) == 0, (tmp_path / "trainer.log").read_text()[-3000:]
        teacher.wait(timeout=60)
        asked = labeler.queries(run_id)
        in_db = {e.query_id: e.label for e in labeler.effective_labels(run_id)}
    epoch_of: dict[int, set[int]] = {}
    for q in asked:
        epoch_of.setdefault(q.session, set()).add(q.epoch)
    sessions_at = [e for epochs in epoch_of.values() for e in epochs]
    assert len(sessions_at) == len(set(sessions_at)), f"a position was asked twice: {epoch_of}"
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    applied = {qid: seg["label"] for qid, seg in ckpt["labelled"].items()}
    total = ckpt["config"]["total_queries"]
    assert applied == in_db and len(applied) == total == len(asked)  # every query asked was used
    assert applied[given] == value


def test_a_revoked_trainer_token_ends_the_run_resumable_in_one_line(tmp_path, service):
    """An operator revokes the token of a trainer waiting for labels: it ends with one line (no
    traceback) and a checkpoint in the wait, and an operator's token resumes the run to its end."""
    api = service.api
    out, log = tmp_path / "trainer", tmp_path / "trainer.log"
    train = train_args(out, api, "--checkpoint-every", "1")
    with CollieClient(api, TOKENS["operator"]) as operator:
        lab_trainer = operator.create_labeler("lab-trainer", role="trainer")
        trainer = cli(*train, "--token", lab_trainer.token, log=log)
        wait_until((out / "service_run.json").exists, alive=trainer, log=log)
        run_id = json.loads((out / "service_run.json").read_text())["run_id"]
        wait_until(lambda: operator.run(run_id).status == "waiting_for_labels")
        stopped_at = operator.run(run_id).epoch
        operator.revoke(lab_trainer.id)
        # it hears the refusal at its next call to the service: the wait's long poll (10 s) returns at
        # the next event of the run, here a policy that changes nothing (no timeout, as before)
        operator.set_feedback_policy(run_id, None)
        assert trainer.wait(timeout=180) == 2
        said = log.read_text()
        assert "Traceback" not in said
        assert f"collie train: error: the labeling service refused the trainer's token for run {run_id}" in said
        assert f"the run is checkpointed at epoch {stopped_at}" in said
        ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
        assert ckpt["epoch"] == stopped_at and [s.query_id for s in ckpt["asking"]] == ["s0-q0", "s0-q1"]
        teacher = cli("teacher", "--api", api, "--run", str(run_id), "--until-done", log=tmp_path / "teacher.log")
        resumed = cli(*train, "--token", TOKENS["operator"], "--resume", log=log)
        assert resumed.wait(timeout=300) == 0, log.read_text()[-3000:]
        teacher.wait(timeout=60)
        assert operator.run(run_id).status == "finished"


@pytest.mark.parametrize("meanwhile", ["nothing", "an operator stopped it"])
def test_a_trainer_killed_before_the_answer_to_its_run_creation_makes_no_second_run_on_restart(
    tmp_path, service, meanwhile
):
    """The service made the run, but the trainer died before it heard so (the answer lost on the way,
    then kill -9): started again, it sends the same creation (OUT/run_creation.json) and continues
    the run the first made. Was: a second run, the first showing "training" on the dashboard for good.
    One an operator stopped meanwhile is not trained again: the start says so."""
    out, log = tmp_path / "trainer", tmp_path / "trainer.log"
    with CollieClient(service.api, TOKENS["operator"]) as operator:
        before = {r.id for r in operator.runs(limit=1000)}
        with stalling_relay(service.api, lose_answer_to=b"POST /api/runs ") as relay:
            trainer = cli(*train_args(out, relay.url), log=log)
            wait_until(lambda: {r.id for r in operator.runs(limit=1000)} - before, alive=trainer, log=log)
            trainer.kill()
            trainer.wait(timeout=30)
        (made,) = {r.id for r in operator.runs(limit=1000)} - before
        assert not (out / "service_run.json").exists()
        if meanwhile != "nothing":
            operator.stop(made)  # its trainer gone, it shows "training (stop requested)"
        again = cli(*train_args(out, service.api), log=log)
        if meanwhile != "nothing":  # the trainer it finds ends it, as the operator asked: no run beside it
            assert again.wait(timeout=120) == 0, log.read_text()[-3000:]
            assert (operator.run(made).status, operator.run(made).control) == ("finished", "stop")
            assert {r.id for r in operator.runs(limit=1000)} - before == {made}
            return
        try:
            wait_until((out / "service_run.json").exists, alive=again, log=log)
            assert json.loads((out / "service_run.json").read_text())["run_id"] == made
            assert {r.id for r in operator.runs(limit=1000)} - before == {made}
            assert not (out / "run_creation.json").exists()
        finally:
            again.terminate()
            again.wait(timeout=60)


def test_a_session_past_the_runs_budget_on_the_service_ends_the_run_in_one_line(tmp_path, service):
    """The service refuses a session past the run's n_total (409): the trainer ends with one line
    naming the budget and a checkpoint, exit 2 (was: the Conflict's traceback, exit 1, which
    `collie up` would restart into the same refusal)."""
    from service.conftest import make_session

    from trainer.config import make_config
    from trainer.envs import make_env

    cfg, env = make_config("smoke", "point"), make_env("point")
    dims = EnvDims(obs_dim=env.obs_dim, nq=env.nq, nv=env.nv, horizon=cfg.segment_length, skill_dim=cfg.skill_dim)
    env.close()
    api = service.api
    with CollieClient(api, TOKENS["trainer"]) as trainer:
        spec = RunCreate(env="point", task="north", method="collie", dims=dims, n_total=2, epochs_total=cfg.epochs)
        run_id = trainer.create_run(spec).id
        trainer.post_session(run_id, make_session(50, 2, dims))  # its whole budget, asked by someone else
        log = tmp_path / "trainer.log"
        refused = cli(*train_args(tmp_path / "run", api, "--run-id", str(run_id)), log=log)
        assert refused.wait(timeout=300) == 2, log.read_text()[-3000:]
        said = log.read_text()
        assert "Traceback" not in said, said[-3000:]
        last = said.strip().splitlines()[-1]
        assert last.startswith(f"collie train: error: the labeling service refused session 0 of run {run_id}")
        assert "budget is 2 queries and 2 are stored" in last and "the run is checkpointed at epoch" in last
        assert "operator's token" not in last  # no token of any kind would be taken


def test_more_epochs_reopen_a_finished_run_and_a_stopped_one_stays_stopped(tmp_path, service):
    """`--resume --epochs` past the end of a run the service holds as finished: the run reopens for the
    epochs added (its sessions are posted, not refused with 409) and finishes at the new end. A run an
    operator stopped in a feedback wait stays stopped when resumed: no session, no traceback."""
    api = service.api
    out, log = tmp_path / "trainer", tmp_path / "trainer.log"
    train = train_args(out, api, "--feedback-timeout", "0.5", "--total-queries", "12")  # nobody labels
    first = cli(*train, "--epochs", "4", log=log)
    assert first.wait(timeout=300) == 0, log.read_text()[-3000:]
    run_id = json.loads((out / "service_run.json").read_text())["run_id"]
    with CollieClient(api, TOKENS["operator"]) as operator:
        before = operator.run(run_id)
        assert (before.status, before.epoch, before.epochs_total) == ("finished", 4, 4)
        asked_before = len(operator.queries(run_id))
        extended = cli(*train, "--resume", "--epochs", "6", log=log)
        assert extended.wait(timeout=300) == 0, log.read_text()[-3000:]
        after = operator.run(run_id)
        assert (after.status, after.epoch, after.epochs_total) == ("finished", 6, 6)
        assert len(operator.queries(run_id)) > asked_before  # the added epochs' sessions went out
        statuses = [e.data for e in operator.events(run_id).events if isinstance(e, StatusEvent)]
        assert any(s.status == "training" and s.message == "extended to 6 epochs" for s in statuses)
        assert "Traceback" not in log.read_text() and not lost_report(log)

        stopped_out, stopped_log = tmp_path / "stopped", tmp_path / "stopped.log"
        waits = train_args(stopped_out, api, "--checkpoint-every", "1")  # labels never come: it waits
        trainer = cli(*waits, log=stopped_log)
        wait_until((stopped_out / "service_run.json").exists, alive=trainer, log=stopped_log)
        stopped_id = json.loads((stopped_out / "service_run.json").read_text())["run_id"]
        wait_until(lambda: operator.run(stopped_id).status == "waiting_for_labels")
        operator.stop(stopped_id)
        assert trainer.wait(timeout=120) == 0, stopped_log.read_text()[-3000:]
        resumed = cli(*waits, "--resume", "--epochs", "12", log=stopped_log)
        assert resumed.wait(timeout=120) == 0, stopped_log.read_text()[-3000:]
        run = operator.run(stopped_id)
        assert (run.status, run.control, run.epochs_total) == ("finished", "stop", 8)  # not extended
        assert f"collie train: warning: run {stopped_id} was stopped by an operator: it is not extended to 12" in (
            stopped_log.read_text()
        )
        assert "Traceback" not in stopped_log.read_text() and not lost_report(stopped_log)


def test_labels_given_before_an_operators_stop_are_applied_before_the_run_ends(tmp_path, service):
    """Was: an operator's stop in a feedback wait ended the run with the session's labels that had
    come unapplied (the checkpoint held fewer than the service counted), and a stopped run is never
    resumed to apply them."""
    out, log = tmp_path / "stopped", tmp_path / "stopped.log"
    trainer = cli(*train_args(out, service.api), log=log)  # smoke: sessions of 2; only we label
    wait_until((out / "service_run.json").exists, alive=trainer, log=log)
    run_id = json.loads((out / "service_run.json").read_text())["run_id"]
    with CollieClient(service.api, TOKENS["operator"]) as operator, CollieClient(service.api, TOKENS["labeler"]) as who:
        wait_until(lambda: operator.run(run_id).status == "waiting_for_labels", alive=trainer, log=log)
        claim = who.claim(run_id)
        assert claim is not None
        who.submit(run_id, claim.query.query_id, 0)  # one of the session's two
        operator.stop(run_id)
        assert trainer.wait(timeout=120) == 0, log.read_text()[-3000:]
        effective = {e.query_id: int(e.label) for e in operator.effective_labels(run_id)}
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    applied = {query_id: int(segment["label"]) for query_id, segment in ckpt["labelled"].items()}
    assert applied == effective == {claim.query.query_id: 0}
    assert ckpt["asking"] is None  # the run ended there: no wait is kept to resume


def lost_report(log: Path) -> bool:
    """Whether the service refused a report, or never took a final status (a routine report the
    service was too busy to answer is best effort: its "not delivered (…busy…)" line is no failure)."""
    return re.search(r"not delivered: |final status \(.*\) not delivered in", log.read_text()) is not None


def test_sessions_nobody_answers_in_time_still_spend_the_budget(service, unanswered):
    """N_total counts the segments asked: with --feedback-timeout and nobody labelling, the smoke
    run asks its 6 (3 sessions of 2) and no more, though its schedule has room for 6 sessions
    (--epochs 12: the fixture `unanswered`)."""
    with CollieClient(service.api, TOKENS["operator"]) as operator:
        asked = operator.queries(unanswered.run_id)
        assert (len(asked), operator.run(unanswered.run_id).n_total) == (6, 6)
        assert sorted({q.session for q in asked}) == [0, 1, 2]


def test_a_run_that_ended_on_the_service_is_refused_to_a_trainer_that_cannot_continue_it(tmp_path, service):
    """Its sessions would all be refused (409) later, in a traceback: a failed run takes none again,
    and a finished or stopped one is continued only from a checkpoint (--resume)."""
    api = service.api
    with CollieClient(api, TOKENS["trainer"]) as trainer:
        dims = EnvDims(obs_dim=4, nq=2, nv=2, horizon=5, skill_dim=2)  # the smoke point run's
        ended = {}
        for status in ("failed", "finished"):
            run = trainer.create_run(RunCreate(env="point", task="north", method="collie", dims=dims, n_total=4))
            trainer.set_status(run.id, status, epoch=3)
            ended[status] = run.id
        log = tmp_path / "trainer.log"
        for status, said in (
            ("failed", "failed on the service: it takes no more sessions (start a new run: another --out)"),
            ("finished", "on the service is finished, and"),
        ):
            out = tmp_path / status
            proc = cli(*train_args(out, api, "--run-id", str(ended[status])), log=log)
            assert proc.wait(timeout=300) == 2
            assert f"collie train: error: run {ended[status]} {said}" in log.read_text()
            assert "Traceback" not in log.read_text()


def test_a_trainer_unlike_the_run_it_is_given_is_refused_naming_the_differences(tmp_path, service, unanswered):
    api, run_id = service.api, unanswered.run_id  # a point north collie run, finished
    log = tmp_path / "trainer.log"
    other = cli(*train_args(tmp_path / "ant", api, "--env", "ant", "--run-id", str(run_id)), log=log)
    assert other.wait(timeout=300) == 2
    said = log.read_text()
    assert (
        f"collie train: error: run {run_id} on the service is not this trainer's: --env ant here, point there" in said
    )
    assert "Traceback" not in said
    named = cli(*train_args(tmp_path / "range", api, "--task", "range", "--run-id", str(run_id)), log=log)
    assert named.wait(timeout=300) == 2  # its metrics would be the run's task's, filed under range
    assert f"run {run_id} on the service is not this trainer's: --task range here, north there" in log.read_text()
    with CollieClient(api, TOKENS["operator"]) as operator:
        assert operator.run(run_id).status == "finished"  # left as it was
        held = operator.run(run_id)
    with CollieClient(api, TOKENS["trainer"]) as trainer:  # a run made for it by hand, judged by Range
        spec = RunCreate(env="point", task="range", method="collie", dims=held.dims, n_total=2, epochs_total=2)
        made = trainer.create_run(spec).id
    follows = train_args(tmp_path / "follows", api, "--epochs", "2", "--feedback-timeout", "0.5")
    unnamed = cli(*follows, "--run-id", str(made), log=log)
    assert unnamed.wait(timeout=300) == 0, log.read_text()[-3000:]  # no --task: it follows the run's
    assert json.loads((tmp_path / "follows" / "config.json").read_text())["task"] == "range"
    assert json.loads((tmp_path / "follows" / "config.json").read_text())["total_queries"] == 2  # the run's budget
    # the service moved (collie up --port 0): a run made by hand holds no config to tell it by, and is
    # not refused for the keys it lacks; a damaged memo is no dead end when the run is named
    memo = tmp_path / "follows" / "service_run.json"
    memo.write_text(json.dumps({"api": "http://127.0.0.1:9", "run_id": made}))
    moved = cli(*follows[:-4], "--feedback-timeout", "0.5", "--epochs", "3", "--resume", "--run-id", str(made), log=log)
    assert moved.wait(timeout=300) == 0, log.read_text()[-3000:]
    memo.write_text("{")
    damaged = cli(
        *follows[:-4], "--feedback-timeout", "0.5", "--epochs", "4", "--resume", "--run-id", str(made), log=log
    )
    assert damaged.wait(timeout=300) == 0, log.read_text()[-3000:]
    assert f"collie train: warning: {memo}: not JSON" in log.read_text()
    budget = cli(*train_args(tmp_path / "budget", api, "--total-queries", "9", "--run-id", str(made)), log=log)
    assert budget.wait(timeout=300) == 2  # it would ask past the budget the run holds (and shows)
    assert f"run {made} on the service is not this trainer's: --total-queries 9 here, 2 there" in log.read_text()
    assert json.loads((tmp_path / "follows" / "summary.json").read_text())["config"]["task"] == "range"

    # a run made before the service kept rules (migration 0007): no rule stored, its task named
    with CollieClient(api, TOKENS["trainer"]) as trainer:
        old = trainer.create_run(spec.model_copy(update={"task": "hole"})).id
    with sqlite3.connect(service.db) as db:
        db.execute("UPDATE runs SET task_definition = NULL WHERE id = ?", (old,))
    older = cli(*train_args(tmp_path / "older", api, "--epochs", "2", "--feedback-timeout", "0.5"), "--run-id",
            str(old), log=log)  # fmt: skip
    assert older.wait(timeout=300) == 0, log.read_text()[-3000:]  # was: "holds neither a task rule nor …"
    assert json.loads((tmp_path / "older" / "task.json").read_text())["definition"]["name"] == "hole"
