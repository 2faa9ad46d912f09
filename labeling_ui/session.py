"""The driver of one browser tab: owns its threads and its I/O around the pure state machine in
tab.py (which decides everything about whether a key may label, and what the worker does next).

Threads: viser's callbacks (keys and buttons: they ask the machine, under the lock, and queue what
it decided), one worker (every service call, in order, and every screen change), the stream
waiter (stream_waiter.py: long-polls the run's event stream while nothing is claimable or in watch
mode, and wakes the worker), and the player (playback.py). While a segment is on screen the next
one is already claimed and prepared (claims.py; the service lets a labeler hold two), so a label
key shows it at once; presenter.py draws each state's screen, identity.py signs in and out,
revisions.py brings one's own labels back (undo, relabel).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Literal

import viser

from collie.client import new_request_id
from collie.labels import Label
from collie.schemas import RunRead
from labeling_ui.actions import Action, Close, Moved, Relabel, Send, SignIn, SignOut, UiConfig, UndoKey, Wake
from labeling_ui.browser import read_identity, remember_tab, save_prefs
from labeling_ui.claims import Claims
from labeling_ui.guarded_tab import GuardedTab
from labeling_ui.identity import Identity
from labeling_ui.presenter import Presenter
from labeling_ui.revisions import Revisions
from labeling_ui.screen import TabScreen
from labeling_ui.service import AuthRefused, Rejected, ServiceDown, ServiceLink
from labeling_ui.sibling_tabs import SiblingTabs, TabMemory
from labeling_ui.stream_waiter import StreamWaiter
from labeling_ui.tab import Key, Phase, Refusal, Rules, Step, Submit, TabState, Withdraw
from labeling_ui.timings import KeyTimings

log = logging.getLogger(__name__)

POLL_S = 0.25  # the worker's tick while idle (skills auto-advance, stream wake-ups)
PROBE_KEY = "collie-probe"  # read to see whether a page still answers (absent: the answer is None)
SLOW_ANSWER_S = 0.5  # a label unanswered this long gets a notice (answers take milliseconds)
SLOW_ANSWER_NOTICE = "The labeling service has not answered yet; your label is kept and sent again until it is taken."


class LabelerSession:
    """Implements panels.Actions for one viser client."""

    def __init__(self, client: viser.ClientHandle, config: UiConfig, siblings: SiblingTabs) -> None:
        """`siblings`: the labeler's other tabs, as the app keeps them (sibling_tabs.py)."""
        self.siblings = siblings
        self.page: str | None = None  # the page load it serves (browser.TabIdentity.page), once read
        self.client = client
        self.config = config
        state = TabState(Rules(config.min_dwell_s, config.min_played))
        self.tab = GuardedTab(state)
        self.screen = TabScreen(client, self, config.fps, state.frame_drawn)  # the player thread's only write
        self.panels, self.scene, self.player = self.screen.panels, self.screen.scene, self.screen.player
        self.timings = KeyTimings()
        self._actions: queue.Queue[Action] = queue.Queue()
        self._retry: Action | None = None
        self._down_since: float | None = None
        self._grace = True
        self._closed = threading.Event()
        self.claims = Claims(self.tab, self.screen, config.prefetch, lambda key: siblings.preloaded(self, key))
        self.waiter = StreamWaiter(f"collie-stream-{client.client_id}", self._closed, config.wait_s, self._actions.put)
        self.presenter = Presenter(
            self.tab,
            self.screen,
            self.claims,
            self.waiter,
            config.fps,
            config.wait_s,
            lambda key: siblings.shown(self, key),
        )
        self.revisions = Revisions(self.tab, self.claims, self.presenter)
        self.identity = Identity(client, config, self.tab, self.claims, self.presenter, self.waiter)
        self._worker = threading.Thread(target=self._work, name=f"collie-labeler-{client.client_id}", daemon=True)

    # ---------------------------------------------------------------- for the app and the tests

    @property
    def state(self) -> TabState:
        """The state machine, read without its lock (tests poll it; the code goes through self.tab)."""
        return self.tab.unguarded

    @property
    def link(self) -> ServiceLink | None:
        """The worker's link to the service (None while signed out)."""
        return self.identity.link

    @property
    def who(self) -> str | None:
        with self.tab as state:
            return state.who

    @property
    def closed(self) -> threading.Event:
        return self._closed

    @property
    def finished(self) -> bool:
        return self._closed.is_set() and not self._worker.is_alive()

    def on_screen_or_held(self) -> set[Key]:
        """The segments this tab shows, has prepared, or holds."""
        with self.tab as state:
            shown = [state.shown] if state.shown else []
            return {s.key for s in shown + state.ahead} | state.held

    def page_open(self, timeout_s: float) -> bool:
        """Whether this tab's page is still there: it answers a round trip (a reload's old connection
        may stay open a moment after its page went). One that is slow to answer counts as open."""
        if self._closed.is_set():
            return False
        try:
            self.client.local_storage.get_item(PROBE_KEY, timeout=timeout_s)
        except TimeoutError:
            return True
        except RuntimeError:  # the connection closed before the answer
            return False
        return True

    def taken_over(self, key: Key, done: Literal["labelled", "skipped"] | None = None) -> None:
        """Another tab of this labeler shows `key` now (`done`: "labelled" or "skipped" it): this
        one must not label it."""
        with self.tab as state:
            was_shown = state.taken_elsewhere(key)
        if was_shown:
            self._actions.put(Moved(key[1], done))

    def handed_back(self, keys: list[Key]) -> None:
        """Another tab of this labeler closed and handed `keys` back: a claim may bring them here."""
        with self.tab as state:
            state.returned(keys)

    def start(self) -> LabelerSession:
        self._worker.start()
        self.waiter.start()
        return self

    def close(self, grace: bool = True) -> None:
        """The tab went away: stop, and hand back its claims (after a grace period in which a
        reload of the tab picks them up again: the new tab's on_show takes them off this one)."""
        self._grace = grace
        with self.tab as state:
            state.close()
        self._closed.set()
        self._actions.put(Close())
        self.player.close()

    def join(self, timeout_s: float) -> None:
        if self._worker.is_alive():
            self._worker.join(timeout_s)

    # ---------------------------------------------------------------- Actions (GUI threads)

    def sign_in(self, token: str) -> None:
        self._actions.put(SignIn(token))

    def sign_out(self) -> None:
        self._actions.put(SignOut())

    def label(self, value: Label) -> None:
        self._press(value)

    def skip(self) -> None:
        self._press("skip")

    def _press(self, value: int | str) -> None:
        with self.tab as state:
            decision = state.press(value, time.perf_counter(), new_request_id())  # type: ignore[arg-type]  # Tab.press takes the label as an int
        if isinstance(decision, Refusal):
            self.panels.notify(decision.title, decision.body, "orange")
        elif decision is not None:
            self._actions.put(Send(decision))

    def undo(self) -> None:
        self._actions.put(UndoKey())

    def relabel(self, query_id: str) -> None:
        self._actions.put(Relabel(query_id))

    def replay(self) -> None:
        self.player.replay()

    def toggle_play(self) -> None:
        self.player.toggle()

    def step(self, frames: int) -> None:
        self.player.step(frames)

    def seek(self, frame: float) -> None:
        self.player.seek(frame)

    def set_speed(self, speed: float) -> None:
        self.player.set_speed(speed)
        self.panels.show_speed(self.player.speed)
        self._save_prefs()

    def set_loop(self, loop: bool) -> None:
        self.player.loop = loop
        with self.tab as state:
            showing = state.phase == Phase.SHOWING
        if showing:
            self.presenter.loop = loop
            self._save_prefs()

    def set_shadows(self, on: bool) -> None:
        self.scene.set_shadows(on)

    def reset_view(self) -> None:
        self.scene.aim_camera()

    def _save_prefs(self) -> None:
        with self.tab as state:
            who, watching = state.who, state.replay_only
        if who is not None and not watching:
            save_prefs(self.client, who, self.presenter.prefs())

    # ---------------------------------------------------------------- the worker

    def _work(self) -> None:
        opened = read_identity(self.client)  # the token, ?watch= and the id of the tab it was opened in
        self.panels.fit_window(opened.window_width)
        self.page = opened.page  # before the app compares it with its other connections' (tab_id)
        tab = self.siblings.tab_id(self, opened.tab)
        if tab != opened.tab:  # a copy of another open tab: a reload of it keeps the id it has now
            remember_tab(self.client, tab)
        memory = self.siblings.tab_memory.setdefault(tab, TabMemory())
        with self.tab as state:
            state.watch_run, state.review = opened.watch, opened.review
            # the labels this tab made before a reload: U walks back through them, unless another signs in
            state.labelled, state.was = memory.labelled, memory.who
        self.identity.tab_id, self.identity.memory = tab, memory  # this tab's claims at the service are its own
        if opened.token:
            self.identity.use_token(opened.token)
        else:
            self.panels.show_login("Paste the labeler token your operator gave you, then **Sign in**.")
        delay = 0.5
        while not self._closed.is_set():
            try:
                self._iterate()
                if self._down_since is not None:
                    self._recovered()
                delay = 0.5
            except ServiceDown as exc:
                self._down_since = self._down_since or time.perf_counter()
                with self.tab as state:
                    signed_in = state.who is not None
                self.presenter.show_outage(str(exc), delay, signed_in)
                self._closed.wait(delay)
                delay = min(delay * 2, self.config.retry_max_s)
            except AuthRefused as exc:
                self.identity.sign_out(f"⚠️ **The service refused this token**: {exc}  \nCheck it and sign in again.")
            except Rejected as exc:  # e.g. a pinned run that does not exist
                self.presenter.show_waiting(f"The service said: {exc}")
                self._closed.wait(self.config.wait_s)
            except Exception as exc:  # keep the tab alive; say what happened
                log.exception("labeling session %s", self.client.client_id)
                self.panels.notify("Unexpected error", repr(exc)[:300], "red")
                with self.tab as state:
                    state.failed()
                self._closed.wait(1.0)
        released = self.claims.release_on_close(self.link, self.config.release_grace_s if self._grace else 0.0)
        self.siblings.released(self, released)

    def _iterate(self) -> None:
        if self._retry is not None:  # an action the outage interrupted, same request id
            action, self._retry = self._retry, None
            self._handle(action)
            return
        with self.tab as state:
            step = state.next_step(self.link is not None, time.monotonic())
        match step:
            case Step.SIGN_IN:
                self._handle(self._actions.get())
            case Step.CHECK:
                self.identity.check_token()
            case Step.ATTEND:
                waited = self._next_action(self.config.lease_s / 3)
                if waited is None:
                    self._renew()
                else:
                    self._handle(waited)
            case Step.REVIEW:
                with self.tab as state:
                    key, role = state.review, state.role
                if key is not None and self.link is not None:
                    self.presenter.review(self.link, key, role)
                self._handle(self._next_action(POLL_S))
            case _:  # WATCH, FIND, IDLE
                if step == Step.FIND and self._show_next():
                    return
                with self.tab as state:
                    run_id = state.idle_run
                self._idle(run_id, watching=step == Step.WATCH)

    def _idle(self, run_id: int | None, watching: bool) -> None:
        """Nothing to label: the run's latest skills play in 3D; a stream event wakes us."""
        if run_id is not None and self.link is not None:
            self.presenter.play_skills(self.link, run_id, watching)
        action = self._next_action(POLL_S)
        if isinstance(action, Wake):
            with self.tab as state:
                state.woken()
            if self.link is not None and "rollouts" in action.kinds:
                self.presenter.new_rollouts(self.link)
        elif action is not None:
            self._handle(action)

    def _next_action(self, timeout_s: float) -> Action | None:
        try:
            return self._actions.get(timeout=timeout_s)
        except queue.Empty:
            return None

    def _handle(self, action: Action | None) -> None:
        try:
            match action:
                case SignIn(token):
                    self.identity.use_token(token)
                case SignOut():
                    self.identity.sign_out("Signed out. Paste a labeler token to sign in again.")
                case _ if self.link is None:
                    return
                case Send(Submit() as submit, at):
                    self._submit(submit, at)
                case Send(Withdraw() as withdraw):
                    self.revisions.withdraw(self.link, withdraw)
                case UndoKey(request_id):
                    self.revisions.undo(self.link, request_id)
                case Relabel(query_id):
                    self.revisions.relabel(self.link, query_id)
                case Moved(query_id, None):
                    self.panels.notify(
                        "Moved to another tab", f"segment {query_id} is open in another of your tabs", "orange"
                    )
                case Moved(query_id, done):
                    self.panels.notify(
                        f"Already {done}",
                        f"segment {query_id} was {done} in another of your tabs, or here before a reload",
                        "gray",
                    )
                    with self.tab as state:  # the worker is the only writer of `shown`
                        state.drop_moved()
                        gone = state.shown is None
                    if gone:  # it no longer labels that one here: the next, or the waiting screen
                        self._show_next()
                case Wake():  # the waiter heard the run of the segment on screen end (presenter.present)
                    self._leave_an_ended_run()
        except ServiceDown:
            self._retry = action
            raise

    # ---------------------------------------------------------------- showing

    def _show_next(self, run: RunRead | None = None) -> bool:
        assert self.link is not None
        return self.presenter.show_next(self.link, run)

    def _leave_an_ended_run(self) -> None:
        """The segment on screen leaves as soon as its run ends, saying so (was: only at the next
        key, whose label was then refused, or the next lease renewal, up to 20 s later)."""
        assert self.link is not None
        shown = self.state.shown
        if shown is not None and (words := self.claims.ended(self.link, shown.run.id)) is not None:
            self.panels.notify("Run closed", words, "orange")
            self._show_next(shown.run)

    def _renew(self) -> None:
        if self.link is not None and (lost := self.claims.renew(self.link)) is not None:
            self._show_next(lost.run)
        elif self.link is not None:  # labels from other tabs and labelers meanwhile: the counts follow
            self.presenter.show_progress(self.link, mine=False)

    def _recovered(self) -> None:
        down_since, self._down_since = self._down_since, None
        with self.tab as state:
            hidden = state.hidden_by_outage(down_since) if down_since is not None else None
        if hidden is not None and self.link is not None:
            self.presenter.present(self.link, hidden)  # the outage screen hid it; show it again

    # ---------------------------------------------------------------- labels

    def _submit(self, submit: Submit, at: float) -> None:
        assert self.link is not None
        segment = submit.segment
        if self.state.shown is not segment:
            return  # a key pressed on a segment that is gone
        reason = None
        try:  # the service refuses it, saying why, unless this tab holds the segment (no lease check first)
            run_id, query_id = segment.key
            value, seconds, request_id = submit.value, submit.seconds, submit.request_id
            with self.panels.notice_if_slow("Sending your label…", SLOW_ANSWER_NOTICE, SLOW_ANSWER_S):
                ack = self.link.submit(
                    run_id, query_id, value, seconds, request_id, segment.revising, self.config.prefetch
                )
            self.claims.next_claim = ack.next  # what to preload, claimed with the label (one round trip, one commit)
        except Rejected as exc:
            reason = self.claims.ended(self.link, segment.run.id) or str(exc)  # an ended run's segments go too
        with self.tab as state:
            if reason is None:
                state.recorded(submit)
            else:
                state.refused(submit)
        if reason is None:  # a reload of this tab may show it meanwhile (this page sent it before it went)
            self.siblings.done(self, segment.key, skipped=submit.value == "skip")
        # no next with the label: the queue is empty, or the run is being stopped (its label still
        # counts), and then what was preloaded of it goes too, not shown until a renewal drops it
        no_next = reason is None and self.config.prefetch and self.claims.next_claim is None
        if no_next and (words := self.claims.ended(self.link, segment.run.id)) is not None:
            self.panels.notify("Run closed", words, "orange")
        if reason is not None:
            self.panels.notify("Not recorded", reason, "red")
        self._show_next(segment.run)
        self.claims.next_claim = None
        shown = self.state.shown
        if shown is not None and shown.appeared is not None and reason is None:
            self.timings.append({"query_id": shown.query.query_id, "key_to_frame_s": shown.appeared - at})
