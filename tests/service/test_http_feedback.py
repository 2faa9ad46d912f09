"""The trainer's HTTP feedback source against a live service: blocking collect, timeout policy,
revisions, pause and stop, history after a restart of the trainer, and a restart of the service."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from backend.main import create_app
from backend.server import BackgroundServer, bind
from collie.client import CollieClient
from collie.schemas import StatusEvent
from trainer.feedback.base import LabelEvent, Segment, StopRequested
from trainer.feedback.http import HttpFeedback
from trainer.telemetry import MetricsReport, RolloutsReport, StatusReport

from .conftest import DIMS, TOKENS, make_run_spec, settings_for


def segments(session: int, n: int, seed: int = 0) -> list[Segment]:
    rng = np.random.default_rng(seed + 100 * session)
    h = DIMS.horizon
    return [
        Segment(
            query_id=f"s{session}-q{j}",
            session=session,
            epoch=10 * session,
            skill=rng.normal(size=DIMS.skill_dim),
            start=j,
            obs=rng.normal(size=(h, DIMS.obs_dim)).astype(np.float32),
            xy=rng.normal(size=(h, 2)),
            pitch=np.where(np.arange(h) == 0, np.nan, rng.normal(size=h)),
            qpos=rng.normal(size=(h, DIMS.nq)),
            qvel=rng.normal(size=(h, DIMS.nv)),
            score=float(j),
            path_xy=rng.normal(size=(20, 2)),
            extra={"note": np.float32(1.5)},
        )
        for j in range(n)
    ]


def rule(query_id: str) -> int:
    return int(query_id.rsplit("q", 1)[1]) % 3


def label_in_background(url: str, run_id: int, count: int, delay_s: float = 0.0) -> threading.Thread:
    """A labeler that labels `count` queries as they come (waiting when the queue is empty)."""

    def work() -> None:
        deadline = time.monotonic() + 120  # a test bug must not hang the suite (a busy machine is slow)
        with CollieClient(url, TOKENS["labeler"]) as client:
            done = 0
            while done < count and time.monotonic() < deadline:
                claim = client.claim(run_id)
                if claim is None:
                    time.sleep(0.02)
                    continue
                time.sleep(delay_s)
                client.submit(run_id, claim.query.query_id, rule(claim.query.query_id))  # type: ignore[arg-type]
                done += 1

    thread = threading.Thread(target=work, daemon=True)
    thread.start()
    return thread


@pytest.fixture
def feedback(live: BackgroundServer) -> Iterator[HttpFeedback]:
    source = HttpFeedback.create(live.url, TOKENS["trainer"], make_run_spec(), wait_chunk_s=2.0)
    yield source
    source.close()


def as_dict(events: list[LabelEvent]) -> dict[str, int | None]:
    return {e.query_id: e.label for e in events}


def test_collect_blocks_until_every_label_is_in(live: BackgroundServer, feedback: HttpFeedback) -> None:
    labeler = label_in_background(live.url, feedback.run_id, 4, delay_s=0.05)
    got = feedback.collect(0, 0, segments(0, 4))
    assert as_dict(got) == {f"s0-q{j}": rule(f"s0-q{j}") for j in range(4)}
    labeler.join()
    assert feedback.revisions() == []
    run = feedback.client.run(feedback.run_id)
    assert run.status == "training" and run.n_labels == 4
    statuses = [e.data.status for e in feedback.client.events(feedback.run_id).events if isinstance(e, StatusEvent)]
    assert statuses == ["training", "waiting_for_labels", "training"]


def test_timeout_policy_goes_on_with_what_arrived(live: BackgroundServer, feedback: HttpFeedback) -> None:
    feedback.timeout_s = 0.5
    started = time.monotonic()
    assert feedback.collect(0, 0, segments(0, 2)) == []
    assert 0.4 < time.monotonic() - started < 30  # returns after the timeout, not never
    label_in_background(live.url, feedback.run_id, 2).join()
    assert as_dict(feedback.revisions()) == {"s0-q0": 0, "s0-q1": 1}  # late labels, once
    assert feedback.revisions() == []


def test_undo_and_relabel_come_back_as_revisions(live: BackgroundServer, feedback: HttpFeedback) -> None:
    label_in_background(live.url, feedback.run_id, 3)
    assert len(feedback.collect(0, 0, segments(0, 3))) == 3
    with CollieClient(live.url, TOKENS["labeler"]) as labeler:
        labeler.undo(feedback.run_id, "s0-q1")
        assert feedback.revisions() == [LabelEvent("s0-q1", None)]
        labeler.submit(feedback.run_id, "s0-q1", 2)
        labeler.submit(feedback.run_id, "s0-q2", 0)  # a revision of my own label (it was 2)
    assert as_dict(feedback.revisions()) == {"s0-q1": 2, "s0-q2": 0}
    assert feedback.revisions() == []


def test_stop_while_waiting_raises(live: BackgroundServer, feedback: HttpFeedback) -> None:
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        threading.Timer(0.3, operator.stop, args=(feedback.run_id,)).start()
        with pytest.raises(StopRequested):
            feedback.collect(0, 0, segments(0, 2))
        assert feedback.control() == "stop"


def test_a_stop_the_trainer_has_not_seen_yet_ends_its_next_session(
    live: BackgroundServer, feedback: HttpFeedback
) -> None:
    """The service refuses the session (409); the trainer ends as at a stop it saw (was: the 409 raised)."""
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.stop(feedback.run_id)
    with pytest.raises(StopRequested, match="stopped by an operator"):
        feedback.collect(0, 0, segments(0, 2))
    assert list(feedback.client.queries(feedback.run_id)) == []


def test_an_interrupt_ends_a_wait_within_one_chunk(feedback: HttpFeedback) -> None:
    """The trainer's signal handler calls interrupt() before it raises: should Python drop that
    raise (in a weakref callback or __del__), the wait still ends, at its next look."""
    threading.Timer(0.3, feedback.interrupt, args=("stopped by signal SIGTERM",)).start()
    started = time.monotonic()
    with pytest.raises(StopRequested, match="SIGTERM"):
        feedback.collect(0, 0, segments(0, 2))
    assert time.monotonic() - started < 10  # one 2 s wait chunk, not the labels that never come


def test_a_session_asked_after_an_interrupt_is_not_posted(feedback: HttpFeedback) -> None:
    """A signal during a feedback epoch's rollout: the trainer stops before people see a session."""
    feedback.interrupt("stopped by signal SIGINT")
    with pytest.raises(StopRequested, match="SIGINT"):
        feedback.collect(0, 0, segments(0, 2))
    assert list(feedback.client.queries(feedback.run_id)) == []


def test_pause_holds_collect_until_resume(live: BackgroundServer, feedback: HttpFeedback) -> None:
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.pause(feedback.run_id)
        assert feedback.control() == "pause"
        assert operator.run(feedback.run_id).status == "paused"
        labeler = label_in_background(live.url, feedback.run_id, 2)  # labelling goes on while paused
        threading.Timer(1.0, operator.resume, args=(feedback.run_id,)).start()
        started = time.monotonic()
        assert len(feedback.collect(0, 0, segments(0, 2))) == 2
        labeler.join()
        assert time.monotonic() - started >= 0.9
        assert feedback.control() == "run" and operator.run(feedback.run_id).status == "training"


def test_a_pause_is_shown_once_at_the_trainers_epoch(live: BackgroundServer, feedback: HttpFeedback) -> None:
    def statuses() -> list[tuple[str, int | None]]:
        page = feedback.client.events(feedback.run_id)
        return [(e.data.status, e.data.epoch) for e in page.events if isinstance(e, StatusEvent)]

    feedback.reporter.status(StatusReport("training", 3))  # the run's last report; the trainer is at 7 now
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.pause(feedback.run_id)
        assert feedback.control(7) == "pause"
        feedback.reporter.status(StatusReport("paused", 7))  # as the training loop says it too
        operator.resume(feedback.run_id)
        assert feedback.control(7) == "run"
    assert statuses()[-2:] == [("paused", 7), ("training", 7)]  # not a "paused" at 3 first (a dashboard's
    assert [s for s, _ in statuses()].count("paused") == 1  # epoch would move while the run is paused)


def test_restarted_trainer_replays_its_sessions_and_asks_nothing_twice(
    live: BackgroundServer, feedback: HttpFeedback
) -> None:
    url, run_id = live.url, feedback.run_id
    label_in_background(url, run_id, 3)
    first = segments(0, 3)
    assert len(feedback.collect(0, 0, first)) == 3
    # Session 1 is posted and partly labelled, then the trainer dies (its collect never returns).
    feedback.timeout_s = 0.1
    feedback.collect(1, 10, segments(1, 4))
    feedback.close()
    label_in_background(url, run_id, 2).join()

    again = HttpFeedback(url, TOKENS["trainer"], run_id, wait_chunk_s=2.0)
    history = again.history()
    assert sorted(s.query_id for s, _ in history) == ["s0-q0", "s0-q1", "s0-q2", "s1-q0", "s1-q1"]
    by_id = {s.query_id: (s, label) for s, label in history}
    stored, label = by_id["s0-q1"]
    assert label == rule("s0-q1")
    np.testing.assert_array_equal(stored.obs, first[1].obs)
    assert np.isnan(stored.pitch[0]) and stored.extra == {"note": 1.5}
    with CollieClient(url, TOKENS["labeler"]) as labeler:  # session 1's leftovers stay open: it is replayed
        assert labeler.queries(run_id, status="retired") == []
    assert again.revisions() == []
    # The replay (from a checkpoint before session 0) reaches sessions 0 and 1 again with other segments:
    # it gets the stored ones back, and waits only for the labels still missing.
    replay0 = segments(0, 3, seed=7)
    assert again.collect(0, 0, replay0) == []  # every label of session 0 is in D already
    assert [s.query_id for s in replay0] == ["s0-q0", "s0-q1", "s0-q2"]
    np.testing.assert_array_equal(replay0[1].obs, first[1].obs)
    label_in_background(url, run_id, 2)
    replay1 = segments(1, 1, seed=7)  # fewer segments (less budget left): the stored four come back
    got = as_dict(again.collect(1, 10, replay1))
    assert [s.query_id for s in replay1] == ["s1-q0", "s1-q1", "s1-q2", "s1-q3"]
    assert set(got) == {"s1-q2", "s1-q3"}
    label_in_background(url, run_id, 2)
    applied = {s.query_id: label for s, label in history} | got | as_dict(again.collect(2, 20, segments(2, 2)))
    with CollieClient(url, TOKENS["trainer"]) as trainer:
        effective = {e.query_id: e.label for e in trainer.effective_labels(run_id)}
        asked = trainer.queries(run_id)
    assert effective == applied and len(applied) == 9  # exactly what the trainer was given
    assert len(asked) == 9 and {q.session for q in asked} == {0, 1, 2}  # no session posted twice
    again.close()


def test_leftovers_of_sessions_the_replay_skips_are_retired(live: BackgroundServer, feedback: HttpFeedback) -> None:
    url, run_id = live.url, feedback.run_id
    feedback.timeout_s = 0.1
    feedback.collect(0, 0, segments(0, 3))  # the trainer moved on with no label (its timeout)
    feedback.close()
    again = HttpFeedback(url, TOKENS["trainer"], run_id, timeout_s=0.1)
    assert again.history() == []
    again.collect(1, 10, segments(1, 1))  # its checkpoint is past session 0: that one is never replayed
    with CollieClient(url, TOKENS["labeler"]) as labeler:
        assert {q.query_id for q in labeler.queries(run_id, status="retired")} == {"s0-q0", "s0-q1", "s0-q2"}
    again.close()


def test_a_restarted_trainer_gets_late_labels_of_the_sessions_it_holds(
    live: BackgroundServer, feedback: HttpFeedback
) -> None:
    url, run_id = live.url, feedback.run_id
    feedback.timeout_s = 0.1
    asked = segments(0, 3)
    assert feedback.collect(0, 0, asked) == []  # the trainer moved on without labels (its timeout)
    feedback.close()
    again = HttpFeedback(url, TOKENS["trainer"], run_id, timeout_s=0.1)  # restarted from a checkpoint holding them
    assert again.history(held=[s.query_id for s in asked]) == []
    label_in_background(url, run_id, 2).join()  # labels come late, after the restart
    assert as_dict(again.revisions()) == {"s0-q0": 0, "s0-q1": 1}  # as they would have before it
    again.collect(1, 10, segments(1, 1))
    with CollieClient(url, TOKENS["labeler"]) as labeler:  # the held one still unlabelled is no leftover
        assert labeler.queries(run_id, status="retired") == []
    again.close()


def test_reposted_session_keeps_the_stored_segments(live: BackgroundServer, feedback: HttpFeedback) -> None:
    feedback.timeout_s = 0.2
    original = segments(0, 2, seed=1)
    feedback.collect(0, 0, original)  # the trainer dies before any label; on restart it re-posts
    again = HttpFeedback(live.url, TOKENS["trainer"], feedback.run_id, wait_chunk_s=2.0)
    assert again.history() == []
    replay = segments(0, 2, seed=2)
    held = replay[0].obs  # the loop keeps references to these arrays
    label_in_background(live.url, feedback.run_id, 2)
    assert len(again.collect(0, 0, replay)) == 2
    np.testing.assert_array_equal(held, original[0].obs)
    np.testing.assert_array_equal(replay[1].qpos, original[1].qpos)
    again.close()


def test_service_restart_mid_session(tmp_path: Path) -> None:
    settings = settings_for(tmp_path / "restart.db")
    # The port is held across the restart, as `collie up` holds the service's (test_stream's restart)
    listener, url = bind("127.0.0.1", 0)
    try:
        server = BackgroundServer(create_app(settings), sock=listener.dup()).start()
        source = HttpFeedback.create(url, TOKENS["trainer"], make_run_spec(), wait_chunk_s=1.0, max_backoff_s=0.2)
        result: list[list[LabelEvent]] = []
        waiting = threading.Thread(target=lambda: result.append(source.collect(0, 0, segments(0, 4))), daemon=True)
        waiting.start()
        with CollieClient(url, TOKENS["labeler"]) as labeler:
            for _ in range(2):
                while (claim := labeler.claim(source.run_id)) is None:
                    time.sleep(0.02)
                labeler.submit(source.run_id, claim.query.query_id, 2)
        server.stop()
        time.sleep(0.5)  # the trainer keeps waiting while the service is down
        server = BackgroundServer(create_app(settings), sock=listener.dup()).start()
        label_in_background(url, source.run_id, 2).join()
        waiting.join(20)
        server.stop()
        source.close()
    finally:
        listener.close()
    assert as_dict(result[0]) == {"s0-q0": 2, "s0-q1": 2, "s0-q2": 2, "s0-q3": 0}


def test_report_is_best_effort_and_bounded(live: BackgroundServer) -> None:
    feedback = HttpFeedback.create(live.url, TOKENS["trainer"], make_run_spec(), report_timeout_s=120)  # busy CI
    record = {"epoch": 5, "safe_ratio": np.float32(0.5), "n_labelled_states": [1, 2, 3], "bad": float("nan"), "s": "x"}
    feedback.reporter.metrics(MetricsReport(5, record))  # type: ignore[arg-type]  # "s": a string is dropped
    feedback.reporter.rollouts(RolloutsReport(5, skills=np.eye(2), xy=np.zeros((100, 5000, 2))))
    feedback.reporter.status(StatusReport("stopped", 6))
    metrics = feedback.client.metrics(feedback.run_id)
    assert metrics[-1].values == {
        "safe_ratio": 0.5,
        "n_labelled_states[0]": 1.0,
        "n_labelled_states[1]": 2.0,
        "n_labelled_states[2]": 3.0,
    }
    rollouts = feedback.client.rollouts(feedback.run_id)[-1].rollouts
    assert len(rollouts) == 64 and len(rollouts[0].xy) == 1000
    assert feedback.client.run(feedback.run_id).status == "finished"
    feedback.close()
    dead = HttpFeedback("http://127.0.0.1:9", TOKENS["trainer"], 1, report_timeout_s=0.5)
    started = time.monotonic()
    for _ in range(20):
        dead.reporter.metrics(MetricsReport(1, {"x": 1.0}))
        dead.reporter.status(StatusReport("training", 1))
        assert dead.revisions() == [] and dead.control() == "run"  # the last known state, at once
    assert time.monotonic() - started < 30  # refused at once (generous for a busy CI box); never raises
    dead.close()


@pytest.mark.parametrize("module", ["backend.main", "trainer.feedback.http"])
def test_no_torch_or_mujoco_on_import(module: str) -> None:
    code = f"import sys, {module}; print(sorted(m for m in ('torch', 'mujoco') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
