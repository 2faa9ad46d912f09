"""Labeler quality control against a live service: redundancy r (distinct labelers, the consensus
rule, one label per query on the stream and for the trainer), and gold segments (served at the
run's rate, scored, never on the trainer's side)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
from alembic import command
from sqlalchemy import text

from backend.db import Database
from backend.migrate import alembic_config, upgrade
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import ClaimRead, LabelChangedEvent, RunRead, WithdrawnEvent
from trainer.feedback.http import HttpFeedback

from .conftest import DIMS, TOKENS, make_run_spec, make_session
from .test_http_feedback import segments

Labelers = Callable[[str], CollieClient]


def label_events_on_stream(client: CollieClient, run_id: int) -> list[tuple[str, str, int | None]]:
    return [
        (e.kind, e.data.query_id, e.data.label)
        for e in client.events(run_id).events
        if isinstance(e, LabelChangedEvent | WithdrawnEvent)
    ]


def test_redundancy_two_needs_two_distinct_labelers(trainer: CollieClient, new_labeler: Labelers) -> None:
    spec = make_run_spec().model_copy(update={"redundancy": 2})
    run = trainer.create_run(spec)
    assert run.redundancy == 2
    trainer.post_session(run.id, make_session(0, 2))
    a, b, c = new_labeler("r2-a"), new_labeler("r2-b"), new_labeler("r2-c")
    assert a.claim(run.id).query.query_id == "0-0"
    first = a.submit(run.id, "0-0", 2)
    assert (first.label, first.query_status) == (None, "pending")  # one label of two: it does not count yet
    assert a.claim(run.id).query.query_id == "0-1"  # never 0-0 again for a
    a.submit(run.id, "0-1", 1)
    assert a.claim(run.id) is None  # a voted on both
    assert label_events_on_stream(trainer, run.id) == [] and trainer.run(run.id).n_labels == 0
    assert trainer.effective_labels(run.id) == [] and list(trainer.labelled(run.id)) == []
    assert b.claim(run.id).query.query_id == "0-0"
    second = b.submit(run.id, "0-0", 2)
    assert (second.label, second.query_status) == (2, "labelled")
    assert b.claim(run.id).query.query_id == "0-1"
    assert b.submit(run.id, "0-1", 0).label == 0  # neutral vs bad: a tie goes to the safer label
    assert c.claim(run.id) is None  # both counted
    assert label_events_on_stream(trainer, run.id) == [("label", "0-0", 2), ("label", "0-1", 0)]
    state = trainer.run(run.id)
    assert state.n_labels == 2 and state.queue.labelled == 2
    assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 2, "0-1": 0}
    assert {i.query.query_id: i.label for i in trainer.labelled(run.id)} == {"0-0": 2, "0-1": 0}
    # a revision that changes the consensus is one more label event (a revision for the trainer)
    assert a.submit(run.id, "0-0", 0).label == 0  # 0 vs 2: a tie, bad
    assert label_events_on_stream(trainer, run.id)[-1] == ("label", "0-0", 0)
    # b withdraws their vote: the query no longer counts and comes back to b to relabel
    undone = b.undo(run.id, "0-1")
    assert (undone.label, undone.query_status) == (None, "leased")
    assert label_events_on_stream(trainer, run.id)[-1] == ("withdrawn", "0-1", None)
    assert trainer.run(run.id).n_labels == 1
    assert b.submit(run.id, "0-1", 1).label == 1  # neutral, neutral
    assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 0, "0-1": 1}
    assert trainer.run(run.id).n_labels == 2


def test_redundancy_refuses_a_second_vote_and_operator_undo_withdraws_all(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run = trainer.create_run(make_run_spec())
    operator.set_quality(run.id, redundancy=2)
    trainer.post_session(run.id, make_session(0, 1))
    a, b = new_labeler("r2op-a"), new_labeler("r2op-b")
    a.claim(run.id)
    a.submit(run.id, "0-0", 1)
    b.claim(run.id)
    with pytest.raises(ApiError) as refused:
        a.undo(run.id, "0-0")  # b holds it now: a may revise, not take it back
    assert refused.value.status == 409 and "revision" in str(refused.value.detail)
    b.submit(run.id, "0-0", 1)
    assert trainer.run(run.id).n_labels == 1
    operator.undo(run.id, "0-0")  # an operator's undo withdraws every vote: two new labels are needed
    assert trainer.run(run.id).n_labels == 0 and trainer.query(run.id, "0-0").status == "pending"
    assert a.claim(run.id).query.query_id == "0-0"  # a's vote is gone: a may label it again
    with pytest.raises(ApiError) as bad:  # the service says what is wrong (raw JSON: the client would refuse)
        operator._send("PUT", f"/runs/{run.id}/quality", json={"redundancy": 0, "gold_rate": 0.9})
    assert bad.value.status == 422 and "redundancy" in str(bad.value.detail) and "gold_rate" in str(bad.value.detail)


def test_the_trainer_receives_one_label_per_query_with_redundancy(live: BackgroundServer) -> None:
    spec = make_run_spec().model_copy(update={"redundancy": 2})
    source = HttpFeedback.create(live.url, TOKENS["trainer"], spec, wait_chunk_s=0.2)
    with CollieClient(live.url, TOKENS["operator"]) as op:
        tokens = [op.create_labeler(f"r2-trainer-{i}-{source.run_id}").token for i in range(2)]
    values = {"s0-q0": (2, 0), "s0-q1": (1, 1), "s0-q2": (2, 2)}  # s0-q0: a tie → bad

    def work(slot: int, token: str) -> None:
        deadline = time.monotonic() + 120  # a test bug must not hang the suite (a busy machine is slow)
        with CollieClient(live.url, token) as client:
            done = 0
            while done < len(values) and time.monotonic() < deadline:
                claim = client.claim(source.run_id)
                if claim is None:
                    time.sleep(0.02)
                    continue
                client.submit(source.run_id, claim.query.query_id, values[claim.query.query_id][slot])  # type: ignore[arg-type]
                done += 1

    threads = [threading.Thread(target=work, args=(i, t), daemon=True) for i, t in enumerate(tokens)]
    for t in threads:
        t.start()
    try:
        got = source.collect(0, 0, segments(0, 3))
        for t in threads:
            t.join(timeout=30)
        assert sorted((e.query_id, e.label) for e in got) == [("s0-q0", 0), ("s0-q1", 1), ("s0-q2", 2)]
        assert source.revisions() == []  # and nothing more: each query reached the trainer once
    finally:
        source.close()


def north_session(session: int, ys: list[float]):  # type: ignore[no-untyped-def]
    """Segments whose task-rule label is known: x = 0.5 at height y (north: neutral above y = |x|;
    range_north: bad beyond 20 of (0, 5), else good above y = |x|, neutral below)."""
    post = make_session(session, len(ys))
    for q, y in zip(post.queries, ys, strict=True):
        q.xy = [[0.5, y + 0.01 * i] for i in range(DIMS.horizon)]
    return post


def test_gold_segments_are_served_scored_and_kept_from_the_trainer(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run = trainer.create_run(make_run_spec(task="north"))
    trainer.post_session(run.id, north_session(0, [1.0, -3.0]))  # oracle: neutral, bad
    a = new_labeler("gold-a")
    for _ in range(2):
        claim = a.claim(run.id)
        a.submit(run.id, claim.query.query_id, 1)
    operator.set_quality(run.id, gold_rate=0.5)
    trainer.post_session(run.id, north_session(1, [1.0, 1.0, 1.0]))
    before = trainer.run(run.id)
    stream_before = trainer.events(run.id).last_id
    # a has 2 labels: gold is due (0 < 0.5 · 3), but a labelled every earlier segment: nothing to re-serve
    assert a.claim(run.id).query.query_id == "1-0"
    a.submit(run.id, "1-0", 1)
    b = new_labeler("gold-b")
    gold = b.claim(run.id)  # b's first segment is gold (0 < 0.5): a copy of 0-0, the oldest earlier one
    assert gold.query.query_id not in {"0-0", "0-1", "1-0", "1-1", "1-2"} and gold.query.session == 1
    assert gold.query.xy == trainer.query(run.id, "0-0").xy
    ack = b.submit(run.id, gold.query.query_id, 1)  # right: the rule says neutral
    assert ack.query_status == "labelled"
    assert b.claim(run.id).query.query_id == "1-1"  # 1 < 0.5 · 2 is false: real work
    b.submit(run.id, "1-1", 1)
    second = b.claim(run.id)  # 1 < 0.5 · 3: gold again, now 0-1 (the rule: bad)
    assert second.query.xy == trainer.query(run.id, "0-1").xy
    b.submit(run.id, second.query.query_id, 1)  # wrong
    # the trainer's side sees none of it
    events = trainer.events(run.id, after=stream_before).events
    assert [(e.kind, e.data.query_id) for e in events if isinstance(e, LabelChangedEvent)] == [
        ("label", "1-0"),
        ("label", "1-1"),
    ]
    assert trainer.run(run.id).n_labels == before.n_labels + 2
    ids = {q.query_id for q in trainer.queries(run.id)}
    assert ids == {"0-0", "0-1", "1-0", "1-1", "1-2"}
    assert {i.query.query_id for i in trainer.labelled(run.id)} == {"0-0", "0-1", "1-0", "1-1"}
    assert gold.query.query_id not in {e.query_id for e in trainer.label_events(run.id)}
    assert trainer.run(run.id).queue.model_dump() == {"pending": 1, "leased": 0, "labelled": 4, "retired": 0}
    # the dashboard scores b's gold
    view = httpx.get(
        f"{live.url}/api/dashboard/runs/{run.id}/labeling",
        headers={"Authorization": f"Bearer {TOKENS['operator']}"},
        timeout=30,
    ).json()
    stats = {s["name"]: s for s in view["labeling"]["labelers"]}
    gold_b = stats["gold-b"]
    assert (gold_b["gold_answered"], gold_b["gold_accuracy"], gold_b["labels"]) == (2, 0.5, 1)
    assert (stats["gold-a"]["gold_answered"], stats["gold-a"]["labels"]) == (0, 3)
    assert view["labeling"]["gold_rate"] == 0.5


def gold_served(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers, name: str
) -> tuple[RunRead, CollieClient, ClaimRead]:
    """A north run whose 0-0 another labeler labelled, gold at 0.5, session 1 posted (1-0, 1-1);
    labeler `name`'s first claim is gold (a copy of 0-0). Returns (run, that labeler, the claim)."""
    run = trainer.create_run(make_run_spec(task="north"))
    trainer.post_session(run.id, north_session(0, [1.0]))
    first = new_labeler(f"{name}-first")
    first.submit(run.id, first.claim(run.id).query.query_id, 1)
    operator.set_quality(run.id, gold_rate=0.5)
    trainer.post_session(run.id, north_session(1, [1.0, 1.0]))
    labeler = new_labeler(name)
    gold = labeler.claim(run.id)
    assert gold is not None and gold.query.query_id not in {"0-0", "1-0", "1-1"}
    return run, labeler, gold


def status_of(live: BackgroundServer, run_id: int, query_id: str) -> str:
    """A query row's status, gold copies included (the API never lists them)."""
    with live.app.state.db.read() as conn:
        found = text("SELECT status FROM queries WHERE run_id = :run AND query_id = :q")
        return str(conn.execute(found, {"run": run_id, "q": query_id}).scalar_one())


def test_a_revoked_labelers_gold_copy_is_retired(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run, b, gold = gold_served(trainer, operator, new_labeler, "gold-revoked")
    operator.revoke(b.me().id)
    assert status_of(live, run.id, gold.query.query_id) == "retired"  # never back in the pool: it is b's
    assert trainer.run(run.id).queue.model_dump() == {"pending": 2, "leased": 0, "labelled": 1, "retired": 0}


def test_a_discard_leaves_the_labelers_gold_answers(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    run, b, gold = gold_served(trainer, operator, new_labeler, "gold-discarded")
    b.submit(run.id, gold.query.query_id, 1)
    real = b.claim(run.id)
    assert real is not None and real.query.query_id == "1-0"
    b.submit(run.id, "1-0", 1)
    gone = operator.discard_votes(run.id, b.me().id)
    assert (gone.queries, gone.withdrawn) == (["1-0"], ["1-0"])  # the gold copy is not among them
    assert status_of(live, run.id, gold.query.query_id) == "labelled"  # their gold answer still measures them


def test_agreement_and_disagreements_on_the_dashboard(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    spec = make_run_spec(task="range_north").model_copy(update={"redundancy": 2})
    run = trainer.create_run(spec)
    trainer.post_session(run.id, north_session(0, [-3.0, -3.0, -30.0]))  # range_north: neutral, neutral, bad
    a, b = new_labeler("agree-a"), new_labeler("agree-b")
    plan = {"agree-a": {"0-0": 1, "0-1": 1, "0-2": 0}, "agree-b": {"0-0": 1, "0-1": 2, "0-2": 0}}
    for who, client in (("agree-a", a), ("agree-b", b)):
        for _ in range(3):
            claim = client.claim(run.id)
            client.submit(run.id, claim.query.query_id, plan[who][claim.query.query_id])  # type: ignore[arg-type]
    a.submit(run.id, "0-2", 2)  # a revision: still one label of a's, and now a disagreement
    a.submit(run.id, "0-2", 0)  # back again
    stats = httpx.get(
        f"{live.url}/api/dashboard/runs/{run.id}/labeling",
        headers={"Authorization": f"Bearer {TOKENS['operator']}"},
        timeout=30,
    ).json()["labeling"]
    # units {1,1}, {1,2}, {0,0}: n = 6, n_0 = 2, n_1 = 3, n_2 = 1; α = 1 − 5 · 2 / (36 − 14) = 6/11
    assert stats["alpha"] == pytest.approx(6 / 11) and stats["alpha_queries"] == 3
    by_name = {s["name"]: s for s in stats["labelers"]}
    assert by_name["agree-a"]["labels"] == 3  # revisions do not count as labels
    assert by_name["agree-a"]["alpha"] == pytest.approx(6 / 11) and by_name["agree-a"]["shared"] == 3
    [odd] = stats["disagreements"]
    assert (odd["query_id"], odd["labels"], odd["effective"], odd["oracle"]) == (
        "0-1",
        {"agree-a": 1, "agree-b": 2},
        1,
        1,
    )
    assert len(odd["xy"]) == DIMS.horizon and stats["n_disagreements"] == 1


def test_a_labeler_never_sees_another_labelers_vote(
    live: BackgroundServer, trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    """With redundancy 2 a query counts once two labelers voted on it independently. A labeler's
    token read the other's vote on a query still open to them: in the dashboard's disagreements
    (labeler → label) and in the run's label events. Now a labeler reads their own events only and
    no disagreements; the operator's and the trainer's reads are unchanged."""
    spec = make_run_spec(task="range_north").model_copy(update={"redundancy": 2})
    run = trainer.create_run(spec)
    trainer.post_session(run.id, north_session(0, [-3.0, -3.0]))
    first, second = new_labeler("votes-first"), new_labeler("votes-second")
    for query_id, label in (("0-0", 2), ("0-1", 1)):  # range_north calls both neutral: 0-0 disagrees with the rule
        claim = first.claim(run.id)
        assert claim is not None and claim.query.query_id == query_id
        first.submit(run.id, query_id, label)  # type: ignore[arg-type]

    def page(token: str, path: str) -> dict:
        url = f"{live.url}/api/dashboard/runs/{run.id}{path}"
        return httpx.get(url, headers={"Authorization": f"Bearer {token}"}, timeout=30).json()

    assert page(TOKENS["operator"], "/labeling")["labeling"]["disagreements"][0]["labels"] == {"votes-first": 2}
    assert page(second.token, "/labeling")["labeling"]["disagreements"] == []
    assert page(second.token, "")["labeling"]["disagreements"] == []  # the whole run page too
    assert page(second.token, "")["labeling"]["n_disagreements"] == 1  # how many, not whose
    assert second.label_events(run.id) == []
    assert [e.query_id for e in first.label_events(run.id)] == ["0-0", "0-1"]  # one's own, as before
    assert len(operator.label_events(run.id)) == len(trainer.label_events(run.id)) == 2


def test_a_0002_database_keeps_its_labels_as_votes(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    db = Database(f"sqlite:///{path}")
    config = alembic_config(db.url)
    with db.engine.begin() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, "0002")
    with db.engine.begin() as conn:
        conn.execute(text("INSERT INTO principals VALUES (1, 'old', 'labeler', 'x', 0, NULL)"))
        conn.execute(
            text(
                "INSERT INTO runs (id, env, task, method, config, dims, status, control, epoch, n_labels,"
                " last_event_id, created_by, created_at, updated_at) VALUES (1, 'point', 'north', 'collie', '{}',"
                " :dims, 'training', 'run', 3, 1, 0, 1, 0, 0)"
            ),
            {"dims": DIMS.model_dump_json()},
        )
        conn.execute(text("INSERT INTO queries VALUES (1, 1, 'q', 0, 0, 0, 0, 'labelled', 1, NULL, 2, 1, 0)"))
        conn.execute(text("INSERT INTO label_events VALUES (1, 1, 1, 1, 'label', 2, NULL, 'r1', NULL, 0)"))
    upgrade(db.engine)
    with db.engine.connect() as conn:
        assert conn.execute(text("SELECT * FROM label_votes")).all() == [(1, 1, 2, 1)]
        assert conn.execute(text("SELECT redundancy, gold_rate FROM runs")).one() == (1, 0.0)
    db.dispose()


def test_label_counts_leave_out_undone_labels(
    live: BackgroundServer, trainer: CollieClient, new_labeler: Labelers
) -> None:
    run = trainer.create_run(make_run_spec())
    trainer.post_session(run.id, make_session(0, 3))
    me = new_labeler("count-undo")
    for value in (2, 0, 1):
        claim = me.claim(run.id)
        me.submit(run.id, claim.query.query_id, value)
    me.undo(run.id, "0-2")  # withdrawn: it comes back to me under a lease, unlabelled
    me.submit(run.id, "0-0", 1)  # a revision
    stats = httpx.get(
        f"{live.url}/api/dashboard/runs/{run.id}/labeling",
        headers={"Authorization": f"Bearer {TOKENS['operator']}"},
        timeout=30,
    ).json()["labeling"]
    [mine] = stats["labelers"]
    assert (mine["labels"], stats["n_labels"], len(me.label_events(run.id))) == (2, 2, 5)


def test_a_skipped_gold_segment_is_not_served_again(trainer: CollieClient, new_labeler: Labelers) -> None:
    run = trainer.create_run(make_run_spec(task="north").model_copy(update={"gold_rate": 0.5}))
    trainer.post_session(run.id, north_session(0, [1.0]))
    first = new_labeler("gold-skip-a")
    assert first.claim(run.id).query.query_id == "0-0"  # the first session: nothing earlier, no gold
    first.submit(run.id, "0-0", 1)
    trainer.post_session(run.id, north_session(1, [1.0]))
    me = new_labeler("gold-skip-b")
    gold = me.claim(run.id)
    assert gold.query.query_id != "1-0" and gold.query.xy == trainer.query(run.id, "0-0").xy
    assert me.skip(run.id, gold.query.query_id).query_status == "retired"
    assert me.claim(run.id).query.query_id == "1-0"  # 0-0 was served to me once: no gold left to serve
    assert trainer.run(run.id).queue.model_dump() == {"pending": 0, "leased": 1, "labelled": 1, "retired": 0}


def gold_labelled(trainer: CollieClient, new_labeler: Labelers, name: str) -> tuple[RunRead, CollieClient, str]:
    """A run whose labeler `name`-b was served a gold copy of 0-0 (labelled by `name`-a) and labelled it."""
    run = trainer.create_run(make_run_spec(task="north").model_copy(update={"gold_rate": 0.5}))
    trainer.post_session(run.id, north_session(0, [1.0]))
    first = new_labeler(f"{name}-a")
    first.claim(run.id)
    first.submit(run.id, "0-0", 1)
    trainer.post_session(run.id, north_session(1, [1.0]))
    me = new_labeler(f"{name}-b")
    gold = me.claim(run.id).query.query_id
    me.submit(run.id, gold, 1)
    return run, me, gold


def test_a_released_gold_segment_is_done_as_a_skipped_one(trainer: CollieClient, new_labeler: Labelers) -> None:
    """Label, undo, release: the gold copy is retired (not left pending with no owner), and its
    original is not served to the same labeler again."""
    run, me, gold = gold_labelled(trainer, new_labeler, "gold-rel")
    me.undo(run.id, gold)
    assert me.release(run.id, gold).status == "retired"
    assert me.claim(run.id).query.query_id == "1-0"  # no gold copy of 0-0 again


def test_an_operators_undo_of_a_gold_label_retires_the_copy(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    """Was: the copy went back to "pending" with its labeler as owner: no claim ever served it
    again, nothing retired it, and its labeler could still label it after the operator's undo."""
    run, me, gold = gold_labelled(trainer, new_labeler, "gold-op")
    assert operator.undo(run.id, gold).query_status == "retired"
    with pytest.raises(ApiError) as err:
        me.submit(run.id, gold, 0)
    assert err.value.status == 409
    assert me.claim(run.id).query.query_id == "1-0"  # no gold copy of 0-0 again
    assert trainer.run(run.id).queue.model_dump() == {"pending": 0, "leased": 1, "labelled": 1, "retired": 0}


def test_a_redundancy_change_keeps_what_counted_and_the_replay_agrees(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    """r raised after a query counted: it stays counted, and a revision still moves its label; r
    lowered while a query waits with enough votes: it counts at once (its labeler cannot vote on it
    again), and stays counted when r rises again. The recomputed view follows every step."""
    run = trainer.create_run(make_run_spec())
    trainer.post_session(run.id, make_session(0, 2))
    a = new_labeler("rc-a")
    a.claim(run.id)
    a.submit(run.id, "0-0", 2)  # counts under r = 1
    operator.set_quality(run.id, redundancy=2)
    a.claim(run.id)
    assert a.submit(run.id, "0-1", 2).query_status == "pending"  # one of two
    assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 2}
    assert a.submit(run.id, "0-0", 0).label == 0  # a revision of a counted query moves its label
    assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 0}
    assert [i.label for i in trainer.labelled(run.id)] == [0] and trainer.run(run.id).n_labels == 1
    assert operator.set_quality(run.id, redundancy=1).n_labels == 2  # 0-1 counts now
    assert label_events_on_stream(trainer, run.id)[-1] == ("label", "0-1", 2)
    for r in (1, 3):  # and stays counted when r rises again
        operator.set_quality(run.id, redundancy=r)
        assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 0, "0-1": 2}
        assert {i.query.query_id: i.label for i in trainer.labelled(run.id)} == {"0-0": 0, "0-1": 2}
    exported = trainer.export(run.id, effective=True)
    assert '"0-0"' in exported and '"0-1"' in exported


def two_votes(
    trainer: CollieClient, operator: CollieClient, a: CollieClient, b: CollieClient, r: int, values: tuple[int, int]
) -> tuple[RunRead, CollieClient, CollieClient]:
    """A run under redundancy r with one query, 0-0, which a and then b label with `values`."""
    run = trainer.create_run(make_run_spec())
    operator.set_quality(run.id, redundancy=r)
    trainer.post_session(run.id, make_session(0, 1))
    for labeler, value in zip((a, b), values, strict=True):
        labeler.claim(run.id)
        labeler.submit(run.id, "0-0", value)
    return run, a, b


def test_a_lowered_redundancy_counts_a_query_whose_second_vote_was_undone(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    """r = 3: a and b vote, b undoes; r lowered to 1 counts a's vote; raised to 2, it stays."""
    run, _, b = two_votes(trainer, operator, new_labeler("ru-a"), new_labeler("ru-b"), 3, (1, 0))
    b.undo(run.id, "0-0")
    b.release(run.id, "0-0")
    operator.set_quality(run.id, redundancy=1)
    assert trainer.query(run.id, "0-0").status == "labelled"
    for r in (1, 2):
        operator.set_quality(run.id, redundancy=r)
        assert {e.query_id: e.label for e in trainer.effective_labels(run.id)} == {"0-0": 1}
    assert b.claim(run.id) is None  # nothing waits any more


def test_a_partial_quality_body_keeps_the_other_field(trainer: CollieClient, operator: CollieClient) -> None:
    run = trainer.create_run(make_run_spec())
    operator.set_quality(run.id, redundancy=3, gold_rate=0.2)
    assert (operator.set_quality(run.id, gold_rate=0.3).redundancy, operator.run(run.id).gold_rate) == (3, 0.3)
    operator._send("PUT", f"/runs/{run.id}/quality", json={})
    assert (operator.run(run.id).redundancy, operator.run(run.id).gold_rate) == (3, 0.3)


def test_only_changes_of_the_effective_label_go_on_the_stream(
    trainer: CollieClient, operator: CollieClient, new_labeler: Labelers
) -> None:
    """r = 2: votes {2, 0} → {0, 0} → {1, 0} keep the effective label 0: one stream event."""
    run, a, b = two_votes(trainer, operator, new_labeler("ch-a"), new_labeler("ch-b"), 2, (2, 0))
    a.submit(run.id, "0-0", 0)
    a.submit(run.id, "0-0", 1)
    assert label_events_on_stream(trainer, run.id) == [("label", "0-0", 0)]
    a.submit(run.id, "0-0", 2)
    b.submit(run.id, "0-0", 2)  # {2, 2}: good
    assert label_events_on_stream(trainer, run.id) == [("label", "0-0", 0), ("label", "0-0", 2)]
    assert all(m.in_effect for m in a.my_labels(run.id) + b.my_labels(run.id))  # both votes stand
