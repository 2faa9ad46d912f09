"""The feedback timeout policy: an operator sets how long the trainer waits for a session's labels
(`POST /runs/{id}/feedback-policy`, a "policy" event on the run's stream); the trainer's
HttpFeedback re-times the session it is waiting on; a database made at revision 0001 upgrades."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import httpx
import pytest
from alembic import command
from alembic.script import ScriptDirectory
from sqlalchemy import inspect, text

from backend.db import Database
from backend.main import create_app
from backend.migrate import alembic_config, upgrade
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import MAX_FEEDBACK_TIMEOUT_S, PolicyEvent, RunCreate
from trainer.feedback.http import HttpFeedback

from .conftest import DIMS, TOKENS, make_run_spec, settings_for
from .test_http_feedback import label_in_background, rule, segments

# ---------------------------------------------------------------- the API


def policy_events(client: CollieClient, run_id: int) -> list[float | None]:
    return [e.data.timeout_s for e in client.events(run_id).events if isinstance(e, PolicyEvent)]


def test_operator_sets_and_clears_the_policy(
    live: BackgroundServer, operator: CollieClient, trainer: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec())
    assert run.feedback_timeout_s is None  # the default: wait for every label
    assert operator.set_feedback_policy(run.id, 30).feedback_timeout_s == 30.0
    assert trainer.run(run.id).feedback_timeout_s == 30.0
    assert operator.set_feedback_policy(run.id, 30.0).feedback_timeout_s == 30.0  # said again: on the stream again
    assert operator.set_feedback_policy(run.id, None).feedback_timeout_s is None
    assert trainer.run(run.id).feedback_timeout_s is None
    assert policy_events(trainer, run.id) == [30.0, 30.0, None]
    page = httpx.get(
        f"{live.url}/api/dashboard/runs/{run.id}", headers={"Authorization": f"Bearer {TOKENS['operator']}"}
    )
    assert page.status_code == 200 and page.json()["run"]["feedback_timeout_s"] is None


def test_the_trainer_stores_its_timeout_at_creation(trainer: CollieClient) -> None:
    spec = make_run_spec().model_copy(update={"feedback_timeout_s": 45.0})
    run = trainer.create_run(spec)
    assert run.feedback_timeout_s == 45.0 and trainer.run(run.id).feedback_timeout_s == 45.0


def test_only_an_operator_may_set_it(operator: CollieClient, trainer: CollieClient, labeler: CollieClient) -> None:
    run = trainer.create_run(make_run_spec())
    for who in (trainer, labeler):
        with pytest.raises(ApiError) as refused:
            who.set_feedback_policy(run.id, 5.0)
        assert refused.value.status == 403
    assert operator.run(run.id).feedback_timeout_s is None and policy_events(operator, run.id) == []


@pytest.mark.parametrize(
    "body",
    [
        '{"timeout_s": -1}',
        '{"timeout_s": 0}',
        '{"timeout_s": "NaN"}',
        '{"timeout_s": NaN}',
        '{"timeout_s": Infinity}',
        '{"timeout_s": 1e300}',
        f'{{"timeout_s": {MAX_FEEDBACK_TIMEOUT_S + 1}}}',
        '{"timeout_s": "30"}',
        "{}",
        '{"timeout_s": 30, "extra": 1}',
    ],
)
def test_bad_values_are_refused(live: BackgroundServer, trainer: CollieClient, body: str) -> None:
    run = trainer.create_run(make_run_spec())
    response = httpx.post(
        f"{live.url}/api/runs/{run.id}/feedback-policy",
        content=body,
        headers={"Authorization": f"Bearer {TOKENS['operator']}", "Content-Type": "application/json"},
    )
    assert response.status_code == 422, response.text
    assert trainer.run(run.id).feedback_timeout_s is None


def test_a_bad_timeout_at_creation_is_refused(live: BackgroundServer) -> None:
    spec = make_run_spec().model_dump(mode="json")
    for bad in (-5, 0, MAX_FEEDBACK_TIMEOUT_S * 2):
        response = httpx.post(
            f"{live.url}/api/runs",
            json={**spec, "feedback_timeout_s": bad},
            headers={"Authorization": f"Bearer {TOKENS['trainer']}"},
        )
        assert response.status_code == 422, response.text
    assert MAX_FEEDBACK_TIMEOUT_S == 7 * 86_400
    with pytest.raises(ValueError):
        RunCreate(env="point", task="north", method="collie", dims=DIMS, feedback_timeout_s=float("nan"))


def test_finished_or_stopping_runs_refuse(operator: CollieClient, trainer: CollieClient) -> None:
    finished = trainer.create_run(make_run_spec())
    trainer.set_status(finished.id, "finished")
    stopping = trainer.create_run(make_run_spec())
    operator.stop(stopping.id)
    for run_id in (finished.id, stopping.id):
        with pytest.raises(ApiError) as refused:
            operator.set_feedback_policy(run_id, 10.0)
        assert refused.value.status == 409
        assert operator.run(run_id).feedback_timeout_s is None
    with pytest.raises(ApiError) as missing:
        operator.set_feedback_policy(987654, 10.0)
    assert missing.value.status == 404


# ---------------------------------------------------------------- the trainer's side


def test_a_shorter_policy_releases_a_waiting_collect(live: BackgroundServer, operator: CollieClient) -> None:
    """No labeler: the trainer waits under a 60 s timeout; an operator sets 0.5 s after ~1 s, which
    has already passed since the session began, so collect returns at once with no labels."""
    spec = make_run_spec().model_copy(update={"feedback_timeout_s": 60.0})
    source = HttpFeedback.create(live.url, TOKENS["trainer"], spec, wait_chunk_s=30.0)
    try:
        assert source.timeout_s == 60.0  # from the spec
        timer = threading.Timer(1.0, operator.set_feedback_policy, args=(source.run_id, 0.5))
        timer.start()
        assert source.collect(0, 0, segments(0, 2)) == []  # no labels: released by a timeout …
        timer.join()
        assert source.timeout_s == 0.5  # … the operator's, not the spec's 60 s
        assert operator.run(source.run_id).status == "training"
    finally:
        source.close()
    restarted = HttpFeedback(live.url, TOKENS["trainer"], source.run_id, timeout_s=60.0)
    try:
        restarted.control()  # replays the log: the operator's policy wins over the constructor's
        assert restarted.timeout_s == 0.5
    finally:
        restarted.close()


def test_clearing_the_policy_waits_for_every_label_again(live: BackgroundServer, operator: CollieClient) -> None:
    """A 1 s timeout from the spec, cleared by an operator before the session is collected: collect
    waits for the labels that arrive well after 1 s instead of returning at 1 s. (The clear is made
    before collect so it cannot land after the 1 s; a policy that changes during the wait:
    test_a_shorter_policy_releases_a_waiting_collect.)"""
    spec = make_run_spec().model_copy(update={"feedback_timeout_s": 1.0})
    source = HttpFeedback.create(live.url, TOKENS["trainer"], spec, wait_chunk_s=30.0)
    try:
        assert source.timeout_s == 1.0  # from the spec, until collect reads the log
        operator.set_feedback_policy(source.run_id, None)

        def label_after_the_timeout() -> None:
            try:
                deadline = time.monotonic() + 60
                while operator.run(source.run_id).status != "waiting_for_labels":  # shown once its clock started
                    if time.monotonic() > deadline:
                        return
                    time.sleep(0.05)
                time.sleep(1.5)  # past the spec's 1 s: under it, collect would have returned without labels
                label_in_background(live.url, source.run_id, 2).join()
            finally:
                if operator.run(source.run_id).n_labels < 2:  # collect would wait for ever: it raises instead
                    source.interrupt("the labeler gave up")

        labeler = threading.Thread(target=label_after_the_timeout, daemon=True)
        labeler.start()
        got = source.collect(0, 0, segments(0, 2))
        labeler.join(60)
        # every label, though they came after the spec's 1 s: the cleared policy waited for them
        assert {e.query_id: e.label for e in got} == {f"s0-q{j}": rule(f"s0-q{j}") for j in range(2)}
        assert source.timeout_s is None
    finally:
        source.close()


# ---------------------------------------------------------------- the migration


def test_a_0001_database_upgrades(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    db = Database(f"sqlite:///{path}")
    config = alembic_config(db.url)
    with db.engine.begin() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, "0001")
    with db.engine.begin() as conn:
        assert "feedback_timeout_s" not in {c["name"] for c in inspect(conn).get_columns("runs")}
        conn.execute(
            text(
                "INSERT INTO principals (id, name, role, token_sha256, created_at) VALUES (1, 'old', 'trainer', 'x', 0)"
            )
        )
        conn.execute(
            text(
                "INSERT INTO runs (id, env, task, method, config, dims, status, control, epoch, n_labels,"
                " last_event_id, created_by, created_at, updated_at) VALUES (1, 'point', 'north', 'collie', '{}',"
                " :dims, 'training', 'run', 3, 0, 0, 1, 0, 0)"
            ),
            {"dims": DIMS.model_dump_json()},
        )
    upgrade(db.engine)
    with db.engine.connect() as conn:
        assert "feedback_timeout_s" in {c["name"] for c in inspect(conn).get_columns("runs")}
        head = ScriptDirectory.from_config(config).get_current_head()
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar_one() == head
        assert conn.execute(text("SELECT epoch, feedback_timeout_s FROM runs")).one() == (3, None)
    db.dispose()
    with (
        BackgroundServer(create_app(settings_for(path))) as server,
        CollieClient(server.url, TOKENS["operator"]) as client,
    ):
        assert client.run(1).feedback_timeout_s is None and client.run(1).epoch == 3
        assert client.set_feedback_policy(1, 12.5).feedback_timeout_s == 12.5
