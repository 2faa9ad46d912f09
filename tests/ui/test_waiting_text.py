"""The waiting screen's words (labeling_ui/waiting.py): the next feedback epoch from the trainer's
schedule, an ETA from its epoch rate, stopped is not finished, and this tab's own claims are never
"being labelled elsewhere"."""

from __future__ import annotations

from datetime import timedelta

from collie.feedback_schedule import next_feedback_epoch
from collie.run_state import run_state
from collie.schemas import MetricsRead, QueueCounts
from labeling_ui.waiting import EpochClock, forecast, waiting_text

from .test_tab_state import NOW, run


def metrics(epoch: int, second: float) -> MetricsRead:
    return MetricsRead(id=epoch, run_id=1, epoch=epoch, values={}, created_at=NOW + timedelta(seconds=second))


def test_next_feedback_epoch_follows_the_trainers_schedule() -> None:
    r = run().model_copy(update={"config": {"warmup": 10, "feedback_every": 5}, "epoch": 3})
    assert next_feedback_epoch(r) == 10
    assert next_feedback_epoch(r.model_copy(update={"epoch": 10})) == 15
    assert next_feedback_epoch(r.model_copy(update={"epoch": 12})) == 15
    assert next_feedback_epoch(r.model_copy(update={"config": {}})) is None
    assert next_feedback_epoch(r.model_copy(update={"n_total": 4, "n_labels": 4})) is None  # budget spent
    asked = QueueCounts(pending=2, leased=1, labelled=0, retired=1)  # asked, not labelled (yet, or ever): spent too
    assert next_feedback_epoch(r.model_copy(update={"n_total": 4, "queue": asked})) is None
    assert next_feedback_epoch(r.model_copy(update={"n_total": 5, "queue": asked})) == 10
    assert next_feedback_epoch(r.model_copy(update={"epoch": 12, "epochs_total": 14})) is None  # past the run's end
    assert next_feedback_epoch(r.model_copy(update={"epoch": 12, "epochs_total": 15})) == 15


def test_eta_from_the_epoch_rate() -> None:
    r = run().model_copy(update={"config": {"warmup": 0, "feedback_every": 20}, "epoch": 10, "status": "training"})
    fc = forecast(r, [metrics(0, 0.0), metrics(10, 5.0)])  # 2 epochs / s
    assert (fc.next_feedback, fc.epochs_per_s, fc.eta_s) == (20, 2.0, 5.0)
    text = waiting_text(r, fc, held_here=0)
    assert "epoch **10**" in text and "epoch **20**" in text and "5 s" in text
    assert forecast(r, [metrics(0, 0.0)]).eta_s is None


def test_stopped_is_not_finished_and_own_claims_are_not_others() -> None:
    stopped = run().model_copy(update={"status": "finished", "control": "stop"})
    assert run_state(stopped) == "stopped"
    assert run_state(run().model_copy(update={"control": "stop"})) == "stopping"
    assert run_state(run().model_copy(update={"status": "finished"})) == "finished"
    mine = run().model_copy(update={"queue": QueueCounts(leased=2)})
    assert "elsewhere" not in waiting_text(mine, forecast(mine, []), held_here=2)
    assert "1 being labelled elsewhere (other labelers, or your other tabs)" in waiting_text(
        mine, forecast(mine, []), held_here=1
    )
    ended = stopped.model_copy(update={"queue": QueueCounts(leased=2)})  # leases that only wait to run out
    assert "elsewhere" not in waiting_text(ended, forecast(ended, []), held_here=0)


def test_a_run_waiting_for_another_tabs_labels_gives_no_eta() -> None:
    """The trainer stands still until the session's last segment (held elsewhere) is labelled."""
    r = run().model_copy(
        update={"config": {"warmup": 40, "feedback_every": 25}, "epoch": 40, "status": "waiting_for_labels"}
    )
    r = r.model_copy(update={"queue": QueueCounts(leased=1, labelled=1)})
    text = waiting_text(r, forecast(r, [metrics(0, 0.0), metrics(40, 20.0)]), held_here=0)
    assert "waits for this session's last labels; the next session (at epoch **65**) comes after it" in text
    assert "in about" not in text and "1 being labelled elsewhere" in text


def test_a_paused_run_gives_no_eta_and_redundancy_says_who_the_segments_wait_for() -> None:
    r = run().model_copy(update={"config": {"warmup": 0, "feedback_every": 20}, "epoch": 10, "control": "pause"})
    text = waiting_text(r, forecast(r, [metrics(0, 0.0), metrics(10, 5.0)]), held_here=0)
    assert "paused it: no feedback session comes until it resumes" in text and "in about" not in text
    both = run().model_copy(update={"redundancy": 2, "queue": QueueCounts(pending=6)})
    assert "6 segment(s) wait for other labelers: each needs labels from 2 different people" in waiting_text(
        both, forecast(both, []), held_here=0
    )
    assert "wait for other labelers" not in waiting_text(
        run().model_copy(update={"queue": QueueCounts(pending=6)}), forecast(run(), []), held_here=0
    )


def test_an_eta_from_the_epochs_the_tab_saw_before_two_metrics_exist() -> None:
    clock = EpochClock()
    r = run().model_copy(update={"config": {"warmup": 240, "feedback_every": 20}, "epoch": 10, "status": "training"})
    assert clock.rate(r, 100.0) is None  # the first look
    assert clock.rate(r.model_copy(update={"epoch": 12}), 102.0) is None  # too short a look
    rate = clock.rate(r.model_copy(update={"epoch": 20}), 110.0)
    assert rate == 1.0
    fc = forecast(r.model_copy(update={"epoch": 20}), [], rate)
    assert fc.eta_s == 220.0 and "in about **4 min**" in waiting_text(r.model_copy(update={"epoch": 20}), fc, 0)
    # the tab's own look wins: the metrics' span holds the waits for labels (was: an ETA of 2 min for 15 s)
    assert forecast(r, [metrics(0, 0.0), metrics(10, 5.0)], rate).epochs_per_s == 1.0
    assert forecast(r, [metrics(0, 0.0), metrics(10, 5.0)], None).epochs_per_s == 2.0  # until it has one
    assert clock.rate(r.model_copy(update={"epoch": 3}), 120.0) is None  # a restarted trainer: look again
    assert clock.rate(r.model_copy(update={"epoch": 5, "control": "pause"}), 130.0) is None
    assert clock.rate(r.model_copy(update={"epoch": 5}), 1000.0) is None  # after a resume: a new first look
    assert clock.rate(r.model_copy(update={"epoch": 15}), 1005.0) == 2.0  # not the pause's long gap
    assert clock.rate(r.model_copy(update={"epoch": 20, "status": "waiting_for_labels"}), 1500.0) is None
    assert clock.rate(r.model_copy(update={"epoch": 20}), 1600.0) is None  # training again: a new first look
    assert clock.rate(r.model_copy(update={"epoch": 30}), 1610.0) == 1.0  # not the wait for labels' gap


def test_a_spent_label_budget_promises_no_session() -> None:
    """Was "The trainer posts the next feedback session when its schedule says so" at 40 / 40."""
    r = run().model_copy(
        update={"config": {"warmup": 0, "feedback_every": 20}, "epoch": 50, "status": "training", "n_total": 40}
    )
    spent = r.model_copy(update={"n_labels": 40, "queue": QueueCounts(labelled=40)})
    text = waiting_text(spent, forecast(spent, []), held_here=0)
    assert "label budget is spent (40 segments asked): no more segments come" in text
    assert "schedule says so" not in text and "Next feedback session" not in text
    open_budget = r.model_copy(update={"n_labels": 20, "queue": QueueCounts(labelled=20)})
    assert "Next feedback session at epoch **60**" in waiting_text(open_budget, forecast(open_budget, []), held_here=0)


def test_collie_ups_progress_line_says_when_the_next_session_comes(capsys) -> None:
    from collie.up import ProgressLine

    r = run().model_copy(update={"config": {"warmup": 240, "feedback_every": 20}, "epoch": 137, "status": "training"})
    line = ProgressLine()
    line.show(r)
    said = capsys.readouterr().err.strip()
    assert said.startswith("training: epoch 137") and said.endswith("· next feedback session at epoch 240")
    line.show(r.model_copy(update={"status": "waiting_for_labels"}))  # it asks now: no "next"
    said = capsys.readouterr().err
    assert said.startswith("waiting for labels: epoch 137") and "next feedback session" not in said
    line.show(r.model_copy(update={"status": "finished", "control": "stop"}))
    assert capsys.readouterr().err.startswith("stopped: epoch 137")  # not "finished"
