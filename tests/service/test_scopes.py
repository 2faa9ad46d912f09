"""Token scopes: a trainer acts only on the runs it created, a labeler may be limited to runs, and
a revoked principal stays revoked — a restart with the same bootstrap token included."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest

from backend.main import create_app
from backend.routes import stream as stream_route
from backend.server import BackgroundServer
from backend.services import auth
from collie.client import ApiError, CollieClient, NotInScope
from collie.schemas import MetricsIn, RolloutsIn, RunRead

from .conftest import TOKENS, make_run_spec, make_session, settings_for


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


@pytest.fixture
def other_trainer(live: BackgroundServer, operator: CollieClient) -> Callable[[str], CollieClient]:
    def make(name: str) -> CollieClient:
        return CollieClient(live.url, operator.create_labeler(name, role="trainer").token)

    return make


def test_a_trainer_acts_only_on_its_own_runs(
    trainer: CollieClient, other_trainer: Callable[[str], CollieClient], run: RunRead
) -> None:

    intruder = other_trainer("trainer-b")
    before = trainer.run(run.id)
    for call in (
        lambda: intruder.post_session(run.id, make_session(5, 1)),
        lambda: intruder.retire(run.id, ["0-0"]),
        lambda: intruder.set_status(run.id, "failed"),
        lambda: intruder.post_metrics(run.id, MetricsIn(epoch=1, values={"x": 1.0})),
        lambda: intruder.post_rollouts(run.id, RolloutsIn(epoch=1, rollouts=[])),
        lambda: list(intruder.labelled(run.id)),
        lambda: intruder.export(run.id),
    ):
        with pytest.raises(NotInScope) as err:
            call()
        assert err.value.status == 403 and "another trainer" in str(err.value.detail)
        assert (err.value.refusal.reason, err.value.refusal.run_id) == ("other_trainer", run.id)
    after = trainer.run(run.id)
    assert (after.status, after.queue, after.last_event_id) == (before.status, before.queue, before.last_event_id)
    assert intruder.run(run.id).id == run.id  # reading stays open to every role
    own = intruder.create_run(make_run_spec())
    assert intruder.post_session(own.id, make_session(0, 1)).created == ["0-0"]
    with pytest.raises(ApiError) as err:
        trainer.set_status(own.id, "failed")  # and the other way round
    assert err.value.status == 403


def test_a_labeler_limited_to_runs(live: BackgroundServer, trainer: CollieClient, operator: CollieClient) -> None:
    mine = trainer.create_run(make_run_spec())
    other = trainer.create_run(make_run_spec())
    for created in (mine, other):
        trainer.post_session(created.id, make_session(0, 2))
    token = operator.create_labeler("scoped", runs=[mine.id]).token
    assert next(p for p in operator.labelers() if p.name == "scoped").runs == [mine.id]
    with CollieClient(live.url, token) as scoped:
        assert scoped.claim(mine.id) is not None
        for call in (
            lambda: scoped.claim(other.id),
            lambda: scoped.run(other.id),
            lambda: scoped.queries(other.id),
            lambda: scoped.events(other.id),
        ):
            with pytest.raises(NotInScope) as err:
                call()
            assert err.value.status == 403 and "limited" in str(err.value.detail)
            assert (err.value.refusal.reason, err.value.refusal.run_id) == ("other_runs", other.id)
        assert [r.id for r in scoped.runs()] == [mine.id]
        with pytest.raises(NotInScope) as err:  # the stream's refusal is as typed as any route's
            next(iter(scoped.stream(other.id)))
        assert (err.value.refusal.reason, err.value.refusal.run_id) == ("other_runs", other.id)
    headers = {"Authorization": f"Bearer {token}"}
    streamed = httpx.get(f"{live.url}/api/runs/{other.id}/stream", headers=headers)
    assert streamed.status_code == 403 and streamed.json()["reason"] == "other_runs"
    wrong_role = httpx.post(f"{live.url}/api/runs", headers=headers, json={})
    assert wrong_role.status_code == 403 and "reason" not in wrong_role.json()  # a role's refusal is no scope's
    page = httpx.get(f"{live.url}/api/dashboard/runs", headers=headers).json()
    assert [r["id"] for r in page["runs"]] == [mine.id]
    body = {"name": "scoped-trainer", "role": "trainer", "runs": [mine.id]}
    response = httpx.post(
        f"{live.url}/api/labelers", json=body, headers={"Authorization": f"Bearer {TOKENS['operator']}"}
    )
    assert response.status_code == 422 and "only a labeler" in response.text


OTHER_SPELLINGS = ("+{}", "{}.0", "%20{}", "{}%20", "{}%09", "%2B0{}", "{}_0")


@pytest.mark.parametrize("spelling", OTHER_SPELLINGS)
def test_a_run_written_another_way_is_refused_not_let_through(
    live: BackgroundServer,
    trainer: CollieClient,
    operator: CollieClient,
    other_trainer: Callable[[str], CollieClient],
    spelling: str,
) -> None:
    """The route's int reads "+1", "1.0", " 1" and "1_0" (run 10) as a run; the scope check read
    only plain digits and let every other form through unchecked. Was: a labeler limited to run 2
    claimed and labelled run 1 at /runs/+1/, and another trainer set its status and posted sessions."""
    target = trainer.create_run(make_run_spec())
    trainer.post_session(target.id, make_session(0, 2))
    mine = trainer.create_run(make_run_spec())
    n = OTHER_SPELLINGS.index(spelling)
    scoped = operator.create_labeler(f"scoped-{n}", runs=[mine.id]).token
    intruder = other_trainer(f"trainer-{n}").token
    raw = spelling.format(target.id)
    before = trainer.run(target.id)
    for token, method, path, body in (
        (scoped, "GET", "", None),
        (scoped, "POST", "/claim", None),
        (scoped, "POST", "/labels", {"query_id": "0-0", "value": 0, "client_request_id": "sc-1"}),
        (intruder, "PUT", "/status", {"status": "training", "epoch": 7, "message": "hijacked"}),
        (intruder, "POST", "/sessions", make_session(5, 1).model_dump(mode="json")),
        (intruder, "GET", "/export", None),
    ):
        answer = httpx.request(
            method, f"{live.url}/api/runs/{raw}{path}", json=body, headers={"Authorization": f"Bearer {token}"}
        )
        assert answer.status_code == 422 and "run_id" in answer.text, (raw, method, path, answer.text)
    after = trainer.run(target.id)
    assert (after.status, after.epoch, after.queue, after.last_event_id) == (
        before.status,
        before.epoch,
        before.queue,
        before.last_event_id,
    )


def test_a_revoked_principal_stays_revoked(tmp_path: Path) -> None:
    settings = settings_for(tmp_path / "revoke.db")
    with BackgroundServer(create_app(settings)) as server, CollieClient(server.url, TOKENS["operator"]) as operator:
        builtin = next(p for p in operator.labelers() if p.name == "labeler")
        assert operator.revoke(builtin.id).revoked
    # the next start supplies the same bootstrap token again: it must not revive the principal
    with BackgroundServer(create_app(settings)) as server, CollieClient(server.url, TOKENS["operator"]) as operator:
        response = httpx.get(f"{server.url}/api/me", headers={"Authorization": f"Bearer {TOKENS['labeler']}"})
        assert response.status_code == 401
        assert next(p for p in operator.labelers() if p.name == "labeler").revoked
        assert operator.me().name == "operator"  # the others are untouched


def test_the_last_operator_cannot_be_revoked(tmp_path: Path) -> None:
    settings = settings_for(tmp_path / "last.db")
    with BackgroundServer(create_app(settings)) as server, CollieClient(server.url, TOKENS["operator"]) as operator:
        me = next(p for p in operator.labelers() if p.name == "operator")
        with pytest.raises(ApiError) as refused:
            operator.revoke(me.id)
        assert refused.value.status == 409 and "last operator" in str(refused.value.detail)
        second = operator.create_labeler("ops-2", role="operator")
        assert operator.revoke(me.id).revoked  # another operator exists now
        with CollieClient(server.url, second.token) as other:
            with pytest.raises(ApiError) as again:
                other.revoke(second.id)
            assert again.value.status == 409


def test_a_labeler_for_a_run_that_does_not_exist_is_refused(operator: CollieClient) -> None:
    with pytest.raises(ApiError) as refused:
        operator.create_labeler("for-nothing", runs=[99999])
    assert refused.value.status == 404 and "no run 99999" in str(refused.value.detail)
    assert "for-nothing" not in [p.name for p in operator.labelers()]


def test_an_operator_changes_a_labelers_runs(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient
) -> None:
    mine, other = trainer.create_run(make_run_spec()), trainer.create_run(make_run_spec())
    for run in (mine, other):
        trainer.post_session(run.id, make_session(0, 2))
    created = operator.create_labeler("movable", runs=[mine.id])
    headers = {"Authorization": f"Bearer {created.token}"}
    with (
        CollieClient(live.url, created.token) as movable,
        httpx.stream("GET", f"{live.url}/api/runs/{mine.id}/stream", headers=headers, timeout=10) as held,
    ):
        lines = held.iter_lines()
        assert next(lines).startswith("retry:")
        assert operator.set_labeler_runs(created.id, [other.id]).runs == [other.id]
        list(lines)  # its stream of `mine` ends now (else: a read timeout)
        assert movable.claim(other.id) is not None  # at once: no wait for a token cache
        with pytest.raises(ApiError) as err:
            movable.run(mine.id)
        assert err.value.status == 403
        assert operator.set_labeler_runs(created.id, None).runs is None  # every run again
        assert {mine.id, other.id} <= {r.id for r in movable.runs()}


def test_a_scope_narrowed_through_another_service_process_ends_its_streams_at_the_heartbeat(
    live: BackgroundServer,
    database_url: str,
    trainer: CollieClient,
    operator: CollieClient,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(stream_route, "HEARTBEAT_S", 0.5)
    mine, other = trainer.create_run(make_run_spec()), trainer.create_run(make_run_spec())
    created = operator.create_labeler("narrowed-elsewhere", runs=[mine.id, other.id])
    headers = {"Authorization": f"Bearer {created.token}"}
    chatting = threading.Event()

    def chatty_trainer(url: str) -> None:  # events more often than the heartbeat: the stream is never silent
        with CollieClient(url, TOKENS["trainer"]) as client:
            epoch = 0
            while not chatting.wait(0.1):
                epoch += 1
                client.post_metrics(mine.id, MetricsIn(epoch=epoch, values={"x": 1.0}))

    with (
        BackgroundServer(create_app(settings_for(database_url))) as elsewhere,  # a second process, one database
        httpx.stream("GET", f"{elsewhere.url}/api/runs/{mine.id}/stream", headers=headers, timeout=10) as held,
    ):
        lines = held.iter_lines()
        assert next(lines).startswith("retry:")
        chat = threading.Thread(target=chatty_trainer, args=(elsewhere.url,), daemon=True)
        chat.start()
        try:
            assert operator.set_labeler_runs(created.id, [other.id]).runs == [other.id]  # through `live`
            deadline = time.monotonic() + 10
            for _ in lines:  # metrics, then the end (the heartbeat reads the scope)
                assert time.monotonic() < deadline, "a stream of a run outside the labeler's runs stayed open"
        finally:
            chatting.set()
            chat.join(10)


def test_a_stream_opening_with_a_cached_scope_that_has_since_narrowed_ends_at_once(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient
) -> None:
    mine, other = trainer.create_run(make_run_spec()), trainer.create_run(make_run_spec())
    created = operator.create_labeler("narrowed-while-opening", runs=[mine.id, other.id])
    with CollieClient(live.url, created.token) as narrowed:
        narrowed.run(mine.id)  # the service's token cache now holds its scope with `mine`
        with live.app.state.db.write() as conn:  # as another service process would: this one's cache stays
            auth.set_runs(conn, created.id, [other.id])
        headers = {"Authorization": f"Bearer {created.token}"}
        with httpx.stream("GET", f"{live.url}/api/runs/{mine.id}/stream", headers=headers, timeout=10) as held:
            assert held.status_code == 200  # its check read the cached scope
            assert [ln for ln in held.iter_lines() if ln.startswith("data:")] == []  # it ends (else: a read timeout)


def test_a_scope_change_is_refused_where_it_makes_no_sense(operator: CollieClient, labeler: CollieClient) -> None:
    created = operator.create_labeler("scope-target")
    as_operator = {"Authorization": f"Bearer {TOKENS['operator']}"}
    url = f"{operator.api}/api/labelers/{created.id}/runs"
    refused = httpx.put(url, json={"runs": []}, headers=as_operator)
    assert refused.status_code == 422 and "valid for no run" in refused.text
    refused = httpx.post(f"{operator.api}/api/labelers", json={"name": "nobody", "runs": []}, headers=as_operator)
    assert refused.status_code == 422 and "valid for no run" in refused.text
    for target, status, words in (
        (next(p.id for p in operator.labelers() if p.name == "trainer"), 422, "only a labeler"),
        (99999, 404, "no principal 99999"),
    ):
        with pytest.raises(ApiError) as err:
            operator.set_labeler_runs(target, None)
        assert err.value.status == status and words in str(err.value.detail)
    with pytest.raises(ApiError) as err:
        labeler.set_labeler_runs(created.id, None)
    assert err.value.status == 403
    operator.revoke(created.id)
    with pytest.raises(ApiError) as err:
        operator.set_labeler_runs(created.id, None)
    assert err.value.status == 409 and "revoked" in str(err.value.detail)
    with pytest.raises(ApiError) as err:
        operator.create_labeler("scope-target")
    assert err.value.status == 409 and "taken by a revoked principal" in str(err.value.detail)
