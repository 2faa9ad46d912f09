"""The labeling tab's pure state machine (labeling_ui/tab.py), state by state: no browser, no
service, no threads (times are arguments)."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest

from collie.schemas import EnvDims, QueryRead, QueueCounts, RunRead
from labeling_ui.tab import CLOSED_RECHECK_S, Phase, Refusal, Rules, Segment, Step, Submit, TabState, Withdraw

NOW = datetime(2026, 12, 1, tzinfo=UTC)


def run(run_id: int = 1) -> RunRead:
    dims = EnvDims(obs_dim=2, nq=2, nv=2, horizon=5, skill_dim=2)
    return RunRead(
        id=run_id, env="point", task="north", method="collie", config={}, dims=dims, status="waiting_for_labels",
        control="run", epoch=3, n_labels=0, n_total=None, epochs_total=None, last_event_id=0, queue=QueueCounts(),
        created_at=NOW, updated_at=NOW,
    )  # fmt: skip


def segment(query_id: str, frames: int = 5, run_id: int = 1, classes: tuple[int, ...] = (0, 1, 2)) -> Segment:
    query = QueryRead(
        run_id=run_id, query_id=query_id, session=0, epoch=3, start=0, score=0.0, status="leased", label=None,
        lease_owner="ann", lease_expires_at=None, created_at=NOW, skill=[1.0, 0.0], obs=[], xy=[[0, 0]] * frames,
        pitch=None, qpos=[[0, 0]] * frames, qvel=[[0, 0]] * frames, path_xy=None, extra={},
    )  # fmt: skip
    return Segment(run(run_id), query, replay=object(), classes=classes)


def showing(seg: Segment, rules: Rules | None = None, at: float = 10.0) -> TabState:
    state = TabState(rules or Rules(min_dwell_s=0.3, min_played=1.0))
    state.use_token("t")
    state.accepted("ann", "labeler")
    state.claimed(seg)
    state.present(seg, at)
    return state


def test_sign_in_then_a_change_of_identity_is_reported() -> None:
    state = TabState()
    assert state.phase == Phase.SIGNED_OUT
    state.use_token("t1")
    assert state.phase == Phase.CHECKING
    assert state.accepted("ann", "labeler") is None
    assert state.phase == Phase.WAITING
    state.use_token("t2")
    assert state.accepted("operator", "operator") == "ann"  # the page says so, loudly
    state.signed_out()
    assert (state.phase, state.who, state.token) == (Phase.SIGNED_OUT, None, None)
    state.use_token("t3")
    assert state.accepted("bob", "labeler") == "operator"  # signing out and in as another is loud too
    state.use_token("t4")
    assert state.accepted("bob", "labeler") is None


def test_watch_mode_is_its_own_phase() -> None:
    state = TabState(watch_run=4)
    state.use_token("t")
    state.accepted("op", "operator")
    assert state.phase == Phase.WATCHING
    assert state.press(1, 100.0, "r") is None  # nothing to label


def test_a_label_before_the_segment_played_once_is_refused_with_a_hint() -> None:
    seg = segment("a", frames=5)
    state = showing(seg)
    decision = state.press(2, 11.0, "r1")
    assert isinstance(decision, Refusal) and "played" in decision.body
    state.frame_drawn(2.0)
    assert isinstance(state.press(2, 11.0, "r1"), Refusal)
    state.frame_drawn(4.0)  # the last frame of five
    decision = state.press(2, 12.5, "r1")
    assert isinstance(decision, Submit) and decision.value == 2
    assert decision.seconds == pytest.approx(2.5)  # from the first frame, not from the claim


def test_the_minimum_is_configurable_and_skip_needs_no_viewing() -> None:
    seg = segment("a", frames=11)
    state = showing(seg, Rules(min_dwell_s=0.0, min_played=0.5))
    state.frame_drawn(4.0)
    assert isinstance(state.press(0, 10.5, "r"), Refusal)
    state.frame_drawn(5.0)
    assert isinstance(state.press(0, 10.5, "r"), Submit)
    fresh = showing(segment("b"))
    assert isinstance(fresh.press("skip", 10.5, "r"), Submit)


def test_a_double_tap_is_ignored_silently() -> None:
    state = showing(segment("a", frames=1))
    assert state.press(1, 10.1, "r") is None  # within the dwell
    assert isinstance(state.press(1, 10.4, "r"), Submit)


def test_a_class_the_task_cannot_give_is_refused() -> None:
    state = showing(segment("a", frames=1, classes=(0, 1)), at=0.0)
    decision = state.press(2, 5.0, "r")
    assert isinstance(decision, Refusal) and "good" in decision.body
    assert isinstance(state.press(0, 5.0, "r"), Submit)


def test_a_segment_taken_over_by_another_tab_is_never_labelled_here() -> None:
    seg = segment("a", frames=1)
    state = showing(seg, at=0.0)
    assert state.taken_elsewhere(seg.key) is True
    decision = state.press(1, 5.0, "r")
    assert isinstance(decision, Refusal) and "another of your tabs" in decision.body
    assert seg.key not in state.held and state.release_all() == []  # and it is not released from here


def test_a_lost_lease_drops_the_segment() -> None:
    seg, nxt = segment("a", frames=1), segment("b", frames=1)
    state = showing(seg, at=0.0)
    assert state.preloaded(nxt)
    lost = state.leases(1, {"b"})
    assert lost == [seg] and state.shown is None and state.phase == Phase.WAITING
    assert state.next_ready() is nxt


def test_preload_is_wanted_once_and_never_duplicates_the_shown_one() -> None:
    seg = segment("a", frames=1)
    state = showing(seg, at=0.0)
    assert state.wants_preload(prefetch=True) and not state.wants_preload(prefetch=False)
    assert not state.preloaded(segment("a"))
    assert state.preloaded(segment("b"))
    assert not state.wants_preload(prefetch=True)


def test_recorded_labels_feed_undo_and_a_withdrawn_segment_comes_back_first() -> None:
    a, b = segment("a", frames=1), segment("b", frames=1)
    state = showing(a, at=0.0)
    state.preloaded(b)
    submit = state.press(1, 5.0, "r1")
    assert isinstance(submit, Submit)
    state.recorded(submit)
    assert state.shown is None and state.labelled == [a.key] and a.key not in state.held
    state.present(state.next_ready() or b, 6.0)
    undo = state.undo_target([], "r2")
    assert undo == Withdraw(1, "a", "r2")
    again = segment("a", frames=1)
    state.withdrawn(undo, again)
    assert state.shown is None and state.next_ready() is again and state.next_ready() is b  # b comes back after
    assert state.labelled == []


def test_undo_after_a_reload_uses_the_services_list() -> None:
    state = TabState()
    assert isinstance(state.undo_target([], "r"), Refusal)
    assert state.undo_target([(1, "z"), (1, "y")], "r") == Withdraw(1, "z", "r")


def test_a_revision_needs_no_lease() -> None:
    seg = segment("a", frames=1)
    seg.revising = True
    state = TabState(Rules(min_dwell_s=0.0, min_played=0.0))
    state.use_token("t")
    state.accepted("ann", "labeler")
    state.present(seg, 0.0)
    state.held.discard(seg.key)
    assert state.leases(1, set()) == [] and state.shown is seg  # a lease renewal does not drop it
    assert isinstance(state.press(2, 1.0, "r"), Submit)


def test_a_refused_label_drops_the_segment() -> None:
    seg = segment("a", frames=1)
    state = showing(seg, Rules(0.0, 0.0), at=0.0)
    submit = state.press(0, 1.0, "r")
    assert isinstance(submit, Submit)
    state.refused(submit)
    assert state.shown is None and seg.key not in state.held and state.labelled == []


def test_the_worker_steps_follow_the_phase() -> None:
    state = TabState()
    assert state.next_step(linked=False, now=0.0) == Step.SIGN_IN
    state.use_token("t")
    assert state.next_step(linked=False, now=0.0) == Step.SIGN_IN  # no link yet: a sign-in is awaited
    assert state.next_step(linked=True, now=0.0) == Step.CHECK
    state.accepted("ann", "labeler")
    assert state.next_step(linked=True, now=0.0) == Step.FIND
    seg = segment("a")
    state.present(seg, 1.0)
    assert state.next_step(linked=True, now=1.0) == Step.ATTEND
    watcher = TabState(watch_run=7)
    watcher.use_token("t")
    watcher.accepted("ann", "labeler")
    assert watcher.next_step(linked=True, now=0.0) == Step.WATCH and watcher.idle_run == 7


def test_nothing_claimable_waits_on_the_stream_until_the_recheck_or_a_wake_up() -> None:
    state = showing(segment("a"))
    waiting = run(3).model_copy(update={"last_event_id": 41})
    state.nothing_claimable(waiting, now=100.0, wait_s=10.0)
    assert (state.shown, state.phase, state.waiting_on, state.idle_run) == (None, Phase.WAITING, (3, 41), 3)
    assert state.next_step(linked=True, now=105.0) == Step.IDLE
    assert state.next_step(linked=True, now=110.0) == Step.FIND
    state.woken()
    assert state.next_step(linked=True, now=101.0) == Step.FIND
    state.nothing_claimable(None, now=100.0, wait_s=10.0)  # no run open at all
    assert state.waiting_on is None and state.idle_run is None and state.recheck_at == 110.0


def test_events_between_the_failed_claim_and_the_runs_read_wake_the_tab() -> None:
    state = showing(segment("a"))
    after_claim = run(3).model_copy(update={"last_event_id": 42})  # a session was posted meanwhile (event 42)
    state.nothing_claimable(after_claim, now=100.0, wait_s=10.0, since=41)
    assert state.waiting_on == (3, 41)  # event 42 wakes the tab at once, not the recheck 10 s on


def test_a_run_that_is_over_is_rechecked_rarely() -> None:
    state = showing(segment("a"))
    for over in (run().model_copy(update={"status": "finished"}), run().model_copy(update={"control": "stop"})):
        state.nothing_claimable(over, now=0.0, wait_s=10.0)
        assert state.recheck_at == CLOSED_RECHECK_S


def test_a_claim_on_screen_in_another_tab_may_not_be_shown_here() -> None:
    a, b = segment("a"), segment("b")
    state = showing(a)
    state.taken_elsewhere(b.key)
    assert not state.may_show(b.key) and state.may_show(segment("c").key)
    state.claimed(b)  # a claim of it answered here (a tab sharing this one's id is handed the same)
    assert not state.may_show(b.key)
    state.claimed(segment("x", run_id=2))
    assert state.held_in(1) == 2 and state.held_in(2) == 1
    state.relabelling(b)  # picked from "my labels" here: this tab shows it now, the other drops it
    assert state.may_show(b.key)


def test_a_segment_another_tab_took_over_leaves_the_screen_and_the_tab_moves_on() -> None:
    a, b = segment("a", frames=1), segment("b", frames=1)
    state = showing(a, Rules(0.0, 0.0), at=0.0)
    assert state.preloaded(b)
    assert state.taken_elsewhere(a.key)  # it was on screen here: the driver is told
    assert state.next_step(linked=True, now=1.0) == Step.FIND  # never stays on it waiting for keys
    assert isinstance(state.press(1, 1.0, "r"), Refusal)
    assert state.drop_moved() is a and state.shown is None and state.phase == Phase.WAITING
    assert state.drop_moved() is None
    assert state.next_ready() is b and state.present(b, 2.0)
    assert isinstance(state.press(1, 3.0, "r"), Submit)  # the next one labels here


def test_a_segment_taken_over_while_it_was_prepared_is_not_shown_here() -> None:
    a, b, c = segment("a"), segment("b"), segment("c")
    state = showing(a)
    state.claimed(b)  # a preload's claim came back; its model is being prepared
    state.taken_elsewhere(b.key)  # meanwhile another tab of this labeler shows it
    assert not state.preloaded(b) and state.next_ready() is None and b.key not in state.held
    state.claimed(c)  # the same for the claim of the next segment to show
    state.taken_elsewhere(c.key)
    assert state.present(c, 11.0) is False and state.shown is a


def test_a_relabel_comes_first_and_the_segment_on_screen_after_it() -> None:
    a, mine = segment("a"), segment("m")
    state = showing(a)
    state.claimed(mine)
    state.relabelling(mine)
    assert mine.revising and mine.key not in state.held  # a revision needs no lease
    assert state.next_ready() is a  # the one on screen comes back once the revision is shown


def test_a_refused_undo_is_walked_past() -> None:
    state = showing(segment("a", frames=1), Rules(0.0, 0.0), at=0.0)
    submit = state.press(0, 1.0, "r")
    assert isinstance(submit, Submit)
    state.recorded(submit)
    undo = state.undo_target([], "u")
    assert isinstance(undo, Withdraw)
    state.undo_refused(undo)
    assert state.labelled == [] and isinstance(state.undo_target([], "u2"), Refusal)


def test_after_an_outage_only_a_segment_it_hid_is_shown_again() -> None:
    seg = segment("a")
    state = showing(seg, at=10.0)
    assert state.hidden_by_outage(down_since=12.0) is seg
    assert state.hidden_by_outage(down_since=9.0) is None  # it appeared after the outage began
    state.failed()
    assert state.shown is None and state.hidden_by_outage(down_since=12.0) is None


def test_review_mode_is_its_own_phase_and_never_labels() -> None:
    state = TabState(Rules(0.0, 0.0), review=(4, "0-1"))
    state.use_token("t")
    state.accepted("op", "operator")
    assert state.phase == Phase.REVIEWING and state.next_step(linked=True, now=0.0) == Step.REVIEW
    for key in (0, 1, 2, "skip"):
        refused = state.press(key, 5.0, "r")  # type: ignore[arg-type]
        assert isinstance(refused, Refusal) and refused.title == "Review only" and "0-1" in refused.body
    refused = state.undo_target([(4, "0-0")], "u")  # even with a label of the operator's in effect
    assert isinstance(refused, Refusal) and refused.title == "Review only"


def test_a_closed_tab_shows_and_preloads_nothing_but_its_label_on_the_way_lands() -> None:
    """A reload replaces the page's connection: the old one must not put a segment on screen (its
    reloaded tab, which goes by the same id, would drop it and hold it unshown for ever)."""
    a, b, c = segment("a", frames=1), segment("b", frames=1), segment("c", frames=1)
    state = showing(a, Rules(0.0, 0.0), at=0.0)
    sent = state.press(1, 1.0, "r")
    assert isinstance(sent, Submit)
    assert state.preloaded(b)
    state.close()
    state.recorded(sent)  # the label pressed before the reload was taken
    assert a.key in state.labelled and state.shown is None
    assert state.next_ready() is b and state.present(b, 2.0) is False and state.shown is None
    assert not state.preloaded(c) and not state.wants_preload(prefetch=True)
    assert b.key in state.release_all()  # handed back after the grace period, unless the reload shows it


def test_a_segment_handed_back_by_the_tab_that_took_it_over_may_be_shown_here_again() -> None:
    a, b = segment("a"), segment("b")
    state = showing(a)
    state.taken_elsewhere(b.key)  # the old connection of this tab showed it
    assert not state.may_show(b.key)
    state.returned([b.key])  # it closed and released it: the next claim of this tab's id may bring it
    assert state.may_show(b.key)
    state.claimed(b)
    assert state.preloaded(b) and state.next_ready() is b
