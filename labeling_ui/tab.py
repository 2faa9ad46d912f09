"""One labeling tab's state machine, pure: no threads, no I/O, no clock (every time is an argument).

The driver (session.py, and on its worker claims.py, presenter.py, identity.py, revisions.py) owns
the threads and the calls to the service; it feeds this machine what happened (a claim came back,
a frame was drawn, a key was pressed, the service answered) and does what it decides (submit this,
show that, say why not, what to do next). Every rule about *whether* a key may label lives here,
so it is tested state by state without a browser (tests/ui/test_tab_state.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from collie.schemas import FINISHED, MAX_HOLD, QueryRead, RunRead, Submission

Key = tuple[int, str]  # (run id, query id)
CLOSED_RECHECK_S = 3600.0  # a finished or stopping run has nothing to claim: its stream wakes the tab, if anything


class Phase(StrEnum):
    SIGNED_OUT = "signed out"  # no token: the sign-in field
    CHECKING = "checking"  # a token, not yet accepted by the service
    WAITING = "waiting"  # signed in, nothing on screen (nothing claimable, or between segments)
    SHOWING = "showing"  # a segment on screen
    WATCHING = "watching"  # ?watch=RUN: the skills of a run, nothing to label
    REVIEWING = "reviewing"  # ?review=RUN&query=ID: one query replayed for an operator, nothing to label


class Step(StrEnum):
    """What the worker does next (TabState.next_step)."""

    SIGN_IN = "sign in"  # no token, or no link to the service: wait for a sign-in
    CHECK = "check"  # ask the service who the token belongs to
    WATCH = "watch"  # watch mode: play the run's skills, wait for its stream
    REVIEW = "review"  # review mode: replay the query under review, wait for the tab's buttons
    FIND = "find"  # nothing on screen: show the next segment, else wait
    IDLE = "idle"  # nothing claimable a moment ago: wait for the stream (or the recheck time)
    ATTEND = "attend"  # a segment on screen: handle the keys, renew its lease when they pause


@dataclass(frozen=True)
class Rules:
    min_dwell_s: float = 0.3  # a key this soon after a segment appears is a double tap: ignored
    min_played: float = 1.0  # share of the segment that must have played once before a label counts
    history: int = 50  # labels `undo` can walk back in this tab (the service keeps all of them)


@dataclass
class Segment:
    """A claimed segment, prepared to show. `replay` is the driver's (a Poser); opaque here."""

    run: RunRead
    query: QueryRead
    replay: Any
    error: str | None = None  # why it cannot be replayed
    appeared: float | None = None  # when its first frame was sent (time-per-label starts here)
    played_to: float = 0.0  # the furthest frame the playhead reached since it appeared
    classes: tuple[int, ...] = (0, 1, 2)  # the labels its task can give (good is absent from single-constraint tasks)
    revising: bool = False  # picked from "my labels": a label on it is a revision of one's own, no lease needed

    @property
    def key(self) -> Key:
        return (self.run.id, self.query.query_id)

    @property
    def n_frames(self) -> int:
        return len(self.query.qpos)

    def seen(self, share: float) -> bool:
        """Played through `share` of its frames at least once (a segment of one frame is seen at once)."""
        last = max(self.n_frames - 1, 0)
        return self.played_to >= share * last - 1e-9


@dataclass(frozen=True)
class Submit:
    """Send this label (0/1/2) or "skip" for this segment; `seconds` from its first frame to the key."""

    segment: Segment
    value: Submission
    seconds: float
    request_id: str


@dataclass(frozen=True)
class Withdraw:
    """Undo the label of this query (its frames come back to relabel)."""

    run_id: int
    query_id: str
    request_id: str


@dataclass(frozen=True)
class Refusal:
    """Why a key did nothing, said on screen."""

    title: str
    body: str


Decision = Submit | Withdraw | Refusal | None


@dataclass
class TabState:
    rules: Rules = field(default_factory=Rules)
    phase: Phase = Phase.SIGNED_OUT
    token: str | None = None
    who: str | None = None  # the signed-in labeler's name, as the service says
    role: str | None = None
    was: str | None = None  # who this tab was last signed in as (a sign-out does not forget it)
    shown: Segment | None = None
    ahead: list[Segment] = field(default_factory=list)  # claimed and prepared, shown next
    held: set[Key] = field(default_factory=set)  # leases this tab holds
    moved: set[Key] = field(default_factory=set)  # segments another tab of this labeler took over
    # this tab's labels, newest last (undo walks back); changed in place: the app keeps it by tab id,
    # so a reloaded tab (a new connection, the same tab) undoes its own labels, not another tab's
    labelled: list[Key] = field(default_factory=list)
    skipped: set[Key] = field(default_factory=set)  # skipped here: one back on screen is said to be
    waiting_on: tuple[int, int] | None = None  # (run, last event id) while nothing is claimable
    recheck_at: float = 0.0  # while waiting: when to try a claim again without a wake-up (monotonic)
    watch_run: int | None = None
    review: Key | None = None  # the query an operator reviews in this tab (it never labels)
    closed: bool = False  # the page went: nothing more is shown here (a label on its way still lands)

    @property
    def replay_only(self) -> bool:
        """Watch or review mode: the tab replays and labels nothing (no prefs, no label buttons)."""
        return self.phase in (Phase.WATCHING, Phase.REVIEWING)

    # ---------------------------------------------------------------- the worker's next step

    def next_step(self, linked: bool, now: float) -> Step:
        """`linked`: the driver holds a link to the service; `now` on the clock of `recheck_at`."""
        if self.phase == Phase.SIGNED_OUT or not linked:
            return Step.SIGN_IN
        if self.phase == Phase.CHECKING:
            return Step.CHECK
        if self.phase == Phase.WATCHING:
            return Step.WATCH
        if self.phase == Phase.REVIEWING:
            return Step.REVIEW
        if self.shown is None or self.shown.key in self.moved:  # never stays on one another tab took over
            return Step.FIND if now >= self.recheck_at else Step.IDLE
        return Step.ATTEND

    def woken(self) -> None:
        """The run's stream carried something: try a claim at once."""
        self.recheck_at = 0.0

    @property
    def idle_run(self) -> int | None:
        """The run whose skills play (and whose stream wakes the tab) while nothing is labelled."""
        if self.phase == Phase.WATCHING:
            return self.watch_run
        return self.waiting_on[0] if self.waiting_on else None

    # ---------------------------------------------------------------- identity

    def use_token(self, token: str) -> None:
        self.forget()
        self.token, self.phase = token, Phase.CHECKING

    def accepted(self, name: str, role: str) -> str | None:
        """The service took the token. Returns the previous name when this tab's identity changed
        (the page says so, loudly), else None."""
        before = self.who or self.was
        if before is not None and before != name:  # another labeler: the labels here are not theirs to undo
            self.labelled.clear()
        self.who, self.role, self.was = name, role, name
        if self.review is not None:
            self.phase = Phase.REVIEWING
        else:
            self.phase = Phase.WATCHING if self.watch_run is not None else Phase.WAITING
        return before if before is not None and before != name else None

    def signed_out(self) -> None:
        self.was = self.who or self.was
        self.forget()
        self.token = self.who = self.role = None
        self.phase = Phase.SIGNED_OUT

    def forget(self) -> None:
        """Everything tied to one sign-in (the driver hands the held claims back first); the tab's
        labels stay until another labeler signs in here (`accepted`)."""
        self.shown, self.waiting_on = None, None
        self.ahead.clear()
        self.held.clear()
        self.moved.clear()

    def close(self) -> None:
        """The page went (a closed tab, or a reload: its new connection is another TabState). A
        segment this one showed now would be taken off the reloaded tab, which then holds it and
        never shows it; a label already sent still lands (its key was pressed before the close)."""
        self.closed = True

    # ---------------------------------------------------------------- claims

    def claimed(self, segment: Segment) -> None:
        # not taken off `moved`: a claim answered before another tab took the segment over, or
        # handed to both tabs of one id, must not bring it back here (present/preloaded refuse it)
        self.held.add(segment.key)

    def may_show(self, key: Key) -> bool:
        """A claim came back for `key`: false when another tab of this labeler took it over here
        (a reload of this tab, or a tab that shared this one's id and so its claims)."""
        return key not in self.moved

    def returned(self, keys: list[Key]) -> None:
        """The tab that took `keys` over from this one closed and handed them back to the pool: a
        later claim may bring them here again, and this tab must then show them (a lease it holds
        and never shows is renewed for as long as the tab is open, and its run waits on it)."""
        self.moved.difference_update(keys)

    def held_in(self, run_id: int) -> int:
        return sum(1 for k in self.held if k[0] == run_id)

    def wants_preload(self, prefetch: bool) -> bool:
        return prefetch and not self.closed and self.shown is not None and not self.ahead and len(self.held) < MAX_HOLD

    def preloaded(self, segment: Segment) -> bool:
        """A second claim came back: keep it to show next unless it is the one on screen, or another
        tab took it over while it was being prepared."""
        if self.closed or segment.key in self.moved or (self.shown is not None and segment.key == self.shown.key):
            return False
        if any(s.key == segment.key for s in self.ahead):
            return False
        self.claimed(segment)
        self.ahead.append(segment)
        return True

    def next_ready(self) -> Segment | None:
        """The prepared segment to show next, if any (taken off the list)."""
        while self.ahead:
            segment = self.ahead.pop(0)
            if segment.key not in self.moved:
                return segment
        return None

    def present(self, segment: Segment, now: float) -> bool:
        """`segment`'s first frame is about to be sent; False (and nothing changes) when another tab
        of this labeler took it over after it was claimed here, or the page went (it is not shown)."""
        if segment.key in self.moved or self.closed:
            return False
        self.claimed(segment)
        segment.appeared, segment.played_to = now, 0.0
        self.shown, self.waiting_on = segment, None
        self.phase = Phase.SHOWING
        return True

    def frame_drawn(self, position: float) -> None:
        if self.shown is not None:
            self.shown.played_to = max(self.shown.played_to, position)

    def nothing_claimable(self, run: RunRead | None, now: float, wait_s: float, since: int | None = None) -> None:
        """No segment to show: wait on `run`'s stream (None: no run is open), and try a claim again
        `wait_s` after `now` without a wake-up (an hour for a run that is over). `since`: the run's
        last event id read before the failed claim; events after it wake the tab (segments posted
        between the claim and `run`'s later read would otherwise wait for the recheck)."""
        self.shown = None
        self.waiting_on = None
        if run is not None:
            self.waiting_on = (run.id, run.last_event_id if since is None else min(since, run.last_event_id))
        over = run is not None and (run.status in FINISHED or run.control == "stop")
        self.recheck_at = now + (CLOSED_RECHECK_S if over else wait_s)
        if self.phase != Phase.SIGNED_OUT:
            self.phase = Phase.WAITING

    def failed(self) -> None:
        """An unexpected error while showing: the segment on screen is dropped (its lease runs out)."""
        self.shown = None

    def hidden_by_outage(self, down_since: float) -> Segment | None:
        """The service is back: the segment on screen if the outage screen hid it (it appeared before)."""
        shown = self.shown
        if shown is not None and (shown.appeared or 0.0) < down_since:
            return shown
        return None

    def leases(self, run_id: int, still: set[str]) -> list[Segment]:
        """The service says which queries of `run_id` this labeler still holds; the segments this tab
        lost meanwhile are dropped and returned (the one on screen first)."""
        lost = []
        for segment in ([self.shown] if self.shown else []) + list(self.ahead):
            if segment.revising:
                continue  # a revision of one's own label holds no lease
            if segment.run.id == run_id and segment.query.query_id not in still:
                lost.append(segment)
                self.held.discard(segment.key)
        self.ahead = [s for s in self.ahead if s not in lost]
        if self.shown is not None and self.shown in lost:
            self.shown = None
            self.phase = Phase.WAITING
        return lost

    def taken_elsewhere(self, key: Key) -> bool:
        """Another tab of this labeler now shows `key` (a reload of this tab, a relabel, or a tab
        that shares this one's id): this tab must not label it. True if it was on screen here: the
        worker then drops it (`drop_moved`) and shows the next (the worker alone changes `shown`)."""
        self.moved.add(key)
        self.held.discard(key)
        self.ahead = [s for s in self.ahead if s.key != key]
        return self.shown is not None and self.shown.key == key

    def drop_moved(self) -> Segment | None:
        """The segment on screen, if another tab took it over: it leaves this tab, which moves on."""
        shown = self.shown
        if shown is None or shown.key not in self.moved:
            return None
        self.shown = None
        self.phase = Phase.WAITING
        return shown

    def release_all(self) -> list[Key]:
        """Hand every claim back (sign-out, a closed tab): the keys to release."""
        keys = sorted(self.held)
        self.held.clear()
        self.ahead.clear()
        return keys

    # ---------------------------------------------------------------- keys

    def press(self, value: Submission, now: float, request_id: str) -> Decision:
        """A label or skip key at `now`, against the segment on screen at that moment."""
        if self.phase == Phase.REVIEWING:
            return self._review_only()
        shown = self.shown
        if shown is None or self.phase != Phase.SHOWING or shown.appeared is None:
            return None
        if shown.key in self.moved:
            return Refusal("Not labelled here", f"segment {shown.query.query_id} is open in another of your tabs")
        if shown.key not in self.held and not shown.revising:
            return Refusal("Not labelled", f"this tab no longer holds segment {shown.query.query_id}")
        if now - shown.appeared < self.rules.min_dwell_s:
            return None  # a double tap or a held key must not label the segment that has only just appeared
        if value == "skip":
            return Submit(shown, value, max(0.0, now - shown.appeared), request_id)
        if shown.error is not None:
            return Refusal("Cannot label", "this segment cannot be replayed; press X to skip it")
        if value not in shown.classes:
            return Refusal("Not a label here", "this task never calls a state good: bad or neutral")
        if not shown.seen(self.rules.min_played):
            share = f"{self.rules.min_played:.0%}" if self.rules.min_played < 1 else "all"
            return Refusal("Watch it first", f"a label counts once {share} of the segment has played once")
        return Submit(shown, value, max(0.0, now - shown.appeared), request_id)

    def recorded(self, submit: Submit) -> None:
        """The service took it: the segment leaves this tab."""
        key = submit.segment.key
        self.held.discard(key)
        if submit.value != "skip":
            self.labelled[:] = [*[k for k in self.labelled if k != key][-(self.rules.history - 1) :], key]
        else:
            self.skipped.add(key)
        if self.shown is submit.segment:
            self.shown = None
            self.phase = Phase.WAITING

    def refused(self, submit: Submit) -> None:
        """The service would not take it (someone else holds it, the run closed): drop it."""
        self.held.discard(submit.segment.key)
        if self.shown is submit.segment:
            self.shown = None
            self.phase = Phase.WAITING

    def undo_target(self, mine: list[tuple[int, str]], request_id: str) -> Decision:
        """Undo the newest label: this tab's, else the newest of `mine` (the labeler's labels still
        in effect, newest first, as the service keeps them: undo works across reloads)."""
        if self.phase == Phase.REVIEWING:
            return self._review_only()
        key = self.labelled[-1] if self.labelled else (mine[0] if mine else None)
        if key is None:
            return Refusal("Nothing to undo", "you have no label in effect in this run")
        return Withdraw(key[0], key[1], request_id)

    def _review_only(self) -> Refusal:
        query = self.review[1] if self.review else "?"
        return Refusal("Review only", f"this tab replays segment {query} for your review: it sends no label")

    def undo_refused(self, withdraw: Withdraw) -> None:
        """The service would not undo it (e.g. already revised elsewhere): undo walks past it."""
        self.labelled[:] = [k for k in self.labelled if k != (withdraw.run_id, withdraw.query_id)]

    def relabelling(self, segment: Segment) -> None:
        """One of this labeler's labelled segments is picked to replay: a label on it is a revision
        (no lease); the segment on screen comes back after it."""
        segment.revising = True
        self.held.discard(segment.key)
        self.moved.discard(segment.key)  # picked here: this tab shows it now (the others drop it)
        if self.shown is not None and self.shown.key != segment.key:
            self.ahead.insert(0, self.shown)

    def withdrawn(self, withdraw: Withdraw, segment: Segment) -> None:
        """The label is undone and its segment claimed again: it is shown next, before whatever
        was on screen (that one comes back after the relabel)."""
        self.labelled[:] = [k for k in self.labelled if k != (withdraw.run_id, withdraw.query_id)]
        if self.shown is not None and self.shown.key != segment.key:
            self.ahead.insert(0, self.shown)
        self.ahead = [s for s in self.ahead if s.key != segment.key]
        self.shown = None
        self.claimed(segment)
        self.moved.discard(segment.key)  # the undo brought it back to this tab
        self.ahead.insert(0, segment)
