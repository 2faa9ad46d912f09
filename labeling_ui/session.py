"""The driver of one browser tab: owns the threads and the I/O around the pure state machine in
tab.py (which decides everything about whether a key may label).

Threads: viser's callbacks (keys and buttons: they ask the machine, under the lock, and queue what
it decided), one worker (every service call, in order, and every screen change), the stream
waiter (long-polls the run's event stream while nothing is claimable or in watch mode, and wakes
the worker), and the player (playback.py). While a segment is on screen the next one is already
claimed and prepared (the service lets a labeler hold two), so a label key shows it at once.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable

import numpy as np
import viser

from collie.client import new_request_id
from collie.labels import Label
from collie.schemas import FINISHED, MAX_HOLD, ClaimRead, QueryRead, RunRead
from labeling_ui.actions import (
    Action,
    Close,
    Moved,
    Relabel,
    Send,
    SignIn,
    SignOut,
    UiConfig,
    UndoKey,
    Wake,
)
from labeling_ui.browser import load_prefs, read_identity, remember_token, save_prefs
from labeling_ui.inset import render_inset
from labeling_ui.models import ModelError, Poser, replay_model
from labeling_ui.panels import SegmentInfo
from labeling_ui.screen import TabScreen
from labeling_ui.service import AuthRefused, MyLabel, Rejected, ServiceDown, ServiceLink
from labeling_ui.tab import Key, Phase, Refusal, Rules, Segment, Submit, TabState, Withdraw
from labeling_ui.waiting import forecast, waiting_text
from labeling_ui.watch import SkillShow

log = logging.getLogger(__name__)

POLL_S = 0.25  # the worker's tick while idle (skills auto-advance, stream wake-ups)


class LabelerSession:
    """Implements panels.Actions for one viser client."""

    def __init__(
        self,
        client: viser.ClientHandle,
        config: UiConfig,
        on_show: Callable[[LabelerSession, Key], None] = lambda *_: None,
    ) -> None:
        self.client = client
        self.config = config
        self.on_show = on_show  # the app tells this labeler's other tabs that this one took a segment
        self.state = TabState(Rules(config.min_dwell_s, config.min_played))
        self._lock = threading.Lock()  # guards self.state across the GUI, worker and app threads
        # the player thread is frame_drawn's only writer
        self.screen = TabScreen(client, self, config.fps, self.state.frame_drawn)
        self.panels, self.scene, self.player = self.screen.panels, self.screen.scene, self.screen.player
        self.link: ServiceLink | None = None
        self.stream_link: ServiceLink | None = None
        self.timings: list[dict[str, float | str]] = []  # key → next first frame, for benchmarks
        self._loop = True  # the labeler's loop setting (the skills between segments use their own)
        self.mine: list[MyLabel] = []  # this labeler's labels in the shown run, newest first (the service's)
        self._skills: SkillShow | None = None
        self._actions: queue.Queue[Action] = queue.Queue()
        self._retry: Action | None = None
        self._down_since: float | None = None
        self._recheck_at = 0.0  # while waiting: when to try a claim again without a wake-up
        self._stream: tuple[int, int] | None = None  # (run, after) the stream waiter long-polls
        self._grace = True
        self._tab: str | None = None  # the browser tab's id (browser.read_identity)
        self._next_claim: ClaimRead | None = None  # the preload a label's answer carried (for _preload)
        self._closed = threading.Event()
        self._worker = threading.Thread(target=self._work, name=f"collie-labeler-{client.client_id}", daemon=True)
        self._waiter = threading.Thread(
            target=self._await_stream, name=f"collie-stream-{client.client_id}", daemon=True
        )

    # ---------------------------------------------------------------- for the app and watch mode

    @property
    def who(self) -> str | None:
        return self.state.who

    @property
    def closed(self) -> threading.Event:
        return self._closed

    @property
    def finished(self) -> bool:
        return self._closed.is_set() and not self._worker.is_alive()

    def on_screen_or_held(self) -> set[Key]:
        """The segments this tab shows, has prepared, or holds."""
        with self._lock:
            shown = [self.state.shown] if self.state.shown else []
            return {s.key for s in shown + self.state.ahead} | self.state.held

    def taken_over(self, key: Key) -> None:
        """Another tab of this labeler shows `key` now: this one must not label it."""
        with self._lock:
            was_shown = self.state.taken_elsewhere(key)
        if was_shown:
            self._actions.put(Moved(key[1]))

    def start(self) -> LabelerSession:
        self._worker.start()
        self._waiter.start()
        return self

    def close(self, grace: bool = True) -> None:
        """The tab went away: stop, and hand back its claims (after a grace period in which a
        reload of the tab picks them up again: the new tab's on_show takes them off this one)."""
        self._grace = grace
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
        with self._lock:
            decision = self.state.press(value, time.perf_counter(), new_request_id())  # type: ignore[arg-type]  # Tab.press takes the label as an int
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
        if self.state.phase == Phase.SHOWING:
            self._loop = loop
            self._save_prefs()

    def set_shadows(self, on: bool) -> None:
        self.scene.set_shadows(on)

    def reset_view(self) -> None:
        self.scene.aim_camera()

    def _save_prefs(self) -> None:
        if self.state.who is not None and self.state.phase != Phase.WATCHING:
            save_prefs(self.client, self.state.who, {"speed": self.player.speed, "loop": self._loop})

    # ---------------------------------------------------------------- the worker

    def _work(self) -> None:
        identity = read_identity(self.client)
        self.state.watch_run = identity.watch
        self._tab = identity.tab  # this tab's claims at the service are its own
        if identity.token:
            self._use_token(identity.token)
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
                self.player.pause()
                self.scene.hide()
                self.panels.show_message(
                    f"⚠️ **The labeling service is unreachable** ({exc}).  \n"
                    f"Retrying in {delay:.0f} s… nothing you labelled is lost."
                )
                self._closed.wait(delay)
                delay = min(delay * 2, self.config.retry_max_s)
            except AuthRefused as exc:
                self._refused(str(exc))
            except Rejected as exc:  # e.g. a pinned run that does not exist
                self._show_waiting(f"The service said: {exc}")
                self._closed.wait(self.config.wait_s)
            except Exception as exc:  # keep the tab alive; say what happened
                log.exception("labeling session %s", self.client.client_id)
                self.panels.notify("Unexpected error", repr(exc)[:300], "red")
                with self._lock:
                    self.state.shown = None
                self._closed.wait(1.0)
        if self._grace and self.state.held:
            time.sleep(self.config.release_grace_s)
        self._release_all()

    def _iterate(self) -> None:
        if self._retry is not None:  # an action the outage interrupted, same request id
            action, self._retry = self._retry, None
            self._handle(action)
            return
        phase = self.state.phase
        if phase == Phase.SIGNED_OUT or self.link is None:
            self._handle(self._actions.get())
        elif phase == Phase.CHECKING:
            self._check_token()
        elif phase == Phase.WATCHING:
            assert self.state.watch_run is not None
            self._idle(self.state.watch_run)
        elif self.state.shown is None:
            if time.monotonic() >= self._recheck_at and self._show_next():
                return
            target = self.state.waiting_on
            self._idle(target[0] if target else None)
        else:
            waited = self._next_action(self.config.lease_s / 3)
            if waited is None:
                self._renew()
            else:
                self._handle(waited)

    def _idle(self, run_id: int | None) -> None:
        """Nothing to label: the run's latest skills play in 3D; a stream event wakes us."""
        if run_id is not None and self.link is not None:
            if self._skills is None or self._skills.run_id != run_id:
                watching = self.state.phase == Phase.WATCHING
                self._skills = SkillShow(self.screen, run_id, self.config.fps, self.watch_stream if watching else None)
                self._skills.reload(self.link)
            self._skills.tick()
        action = self._next_action(POLL_S)
        if isinstance(action, Wake):
            self._recheck_at = 0.0
            if self._skills is not None and self.link is not None and "rollouts" in action.kinds:
                self._skills.reload(self.link)
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
                    self._use_token(token)
                case SignOut():
                    self._release_all()
                    remember_token(self.client, None)
                    self._stop_link()
                    with self._lock:
                        self.state.signed_out()
                    self.panels.show_login("Signed out. Paste a labeler token to sign in again.")
                case _ if self.link is None:
                    return
                case Send(Submit() as submit, at):
                    self._submit(submit, at)
                case Send(Withdraw() as withdraw):
                    self._withdraw(withdraw)
                case UndoKey(request_id):
                    self._undo(request_id)
                case Relabel(query_id):
                    self._relabel(query_id)
                case Moved(query_id):
                    self.panels.notify(
                        "Moved to another tab", f"segment {query_id} is open in another of your tabs", "orange"
                    )
                    if self.state.shown is None:
                        self._show_next()
        except ServiceDown:
            self._retry = action
            raise

    # ---------------------------------------------------------------- signing in

    def _use_token(self, token: str) -> None:
        self._release_all()
        self._stop_link()
        if not token:
            self.panels.show_login("Type a token first.")
            return
        with self._lock:
            self.state.use_token(token)
        self.panels.show_message("Checking your token…")
        self.link = ServiceLink(self.config.api, token, self.config.run_id, self.config.lease_s, self._tab)
        self.stream_link = ServiceLink(self.config.api, token, self.config.run_id, self.config.lease_s, self._tab)
        remember_token(self.client, token)

    def _check_token(self) -> None:
        assert self.link is not None
        me = self.link.login()
        with self._lock:
            before = self.state.accepted(me.name, me.role)
        self.panels.greet(me.name, me.role, before)
        if before is not None:  # loud: this tab was someone else a moment ago
            self.panels.notify("You are now " + me.name, f"this tab was signed in as {before}", "red")
        prefs = load_prefs(self.client, me.name) if self.state.phase != Phase.WATCHING else {}
        speed, loop = prefs.get("speed"), prefs.get("loop")
        if isinstance(speed, int | float):
            self.player.set_speed(float(speed))
        if isinstance(loop, bool):
            self._loop = self.player.loop = loop
            self.panels.loop.value = loop  # type: ignore[misc]  # viser types .value read-only; it is settable
        self.panels.show_speed(self.player.speed)
        if self.state.phase == Phase.WAITING:
            self.panels.show_message("Looking for segments to label…")

    def _stop_link(self) -> None:
        for link in (self.link, self.stream_link):
            if link is not None:
                link.close()
        self.link = self.stream_link = None
        self._stream = None
        self._skills = None
        self.mine = []
        self.player.unload()
        self.scene.hide()

    def _refused(self, detail: str) -> None:
        """A refused token signs out this tab only (its own sessionStorage)."""
        self._release_all()
        self._stop_link()
        remember_token(self.client, None)
        with self._lock:
            self.state.signed_out()
        self.panels.show_login(f"⚠️ **The service refused this token**: {detail}  \nCheck it and sign in again.")

    # ---------------------------------------------------------------- claiming and showing

    def _show_next(self, run: RunRead | None = None) -> bool:
        """Show the next segment (the prepared one, else a fresh claim); False (and the waiting
        screen) when there is none."""
        assert self.link is not None
        with self._lock:
            ready = self.state.next_ready()
        if ready is not None:
            self._present(ready)
            return True
        claim = self._claim(run) if run is not None else None
        if claim is None:
            run = self.link.pick_run()
            if run is None:
                self._wait_for(None, "No run is open on the service yet.")
                return False
            claim = self._claim(run)
        if claim is None:
            assert run is not None
            self._wait_for(run, None)
            return False
        self._present(self._prepare(*claim))
        return True

    def _claim(self, run: RunRead) -> tuple[RunRead, QueryRead] | None:
        """A segment this tab may show: a fresh claim, or one this labeler holds that no other of
        its tabs shows (the service keeps claims per labeler)."""
        assert self.link is not None
        for hold in (1, MAX_HOLD):
            try:
                claimed = self.link.claim(run.id, hold=hold)
            except Rejected:  # the run stopped or finished meanwhile
                return None
            if claimed is None:
                return None
            if (run.id, claimed.query.query_id) not in self.state.moved:
                return run, claimed.query
        return None  # both of this labeler's claims are on screen in other tabs

    def _wait_for(self, run: RunRead | None, status: str | None) -> None:
        assert self.link is not None
        run = self.link.run(run.id) if run is not None else None  # fresh counts, after our own claims
        with self._lock:
            self.state.nothing_claimable(run.id if run else None, run.last_event_id if run else 0)
            held_here = sum(1 for k in self.state.held if run is not None and k[0] == run.id)
        self._stream = self.state.waiting_on
        self._recheck_at = time.monotonic() + self.config.wait_s
        if run is not None:
            status = waiting_text(run, forecast(run, self.link.metrics(run.id)), held_here)
            if run.status in FINISHED or run.control == "stop":
                self._recheck_at = time.monotonic() + 3600.0
            self._load_mine(run)
        skills = self._skills
        self._show_waiting(status or "", keep_skills=skills is not None and run is not None and skills.run_id == run.id)

    def _show_waiting(self, status: str, keep_skills: bool = False) -> None:
        """The waiting screen; the skills of the run's latest evaluation keep playing if they are on."""
        if not keep_skills:
            self._skills = None
            self.player.unload()
            self.scene.hide()
        self.panels.show_message(
            f"☕ **Nothing to label right now.**  \n{status}  \nNew segments appear here by themselves.",
            keep_replay=keep_skills,
        )

    def _prepare(self, run: RunRead, query: QueryRead) -> Segment:
        """A claimed segment made ready to show: its model compiled and its frames checked."""
        with self._lock:
            self.state.claimed(Segment(run, query, None))
        task = self.screen.task_of(run)
        classes = (0, 1, 2) if task is None or task.can_be_good else (0, 1)
        try:
            poser = Poser(replay_model(run.env), np.asarray(query.qpos, float))
            return Segment(run, query, poser, classes=classes)
        except ModelError as exc:
            return Segment(run, query, None, str(exc), classes=classes)

    def _present(self, segment: Segment) -> None:
        run, query = segment.run, segment.query
        poser: Poser | None = segment.replay
        if poser is not None:
            try:
                self.scene.load(run.env)  # builds the robot when the env changes
            except ModelError as exc:
                poser, segment.error, segment.replay = None, str(exc), None
        self._skills = None
        self._stream = None
        self.player.fps = self.config.fps
        if self.player.loop != self._loop:  # the skills shown while waiting may have changed it
            self.player.loop = self._loop
            self.panels.loop.value = self._loop  # type: ignore[misc]  # viser types .value read-only; it is settable
        task = self.screen.task_of(run)
        info = SegmentInfo(
            query.query_id, run.id, run.env, run.task, run.method, query.epoch, query.session, query.start,
            query.skill, len(query.qpos), segment.revising,
        )  # fmt: skip
        earlier = np.asarray(query.path_xy, float)[: query.start + 1] if query.path_xy else None
        with self._lock:  # keys from now on apply to this segment
            self.state.present(segment, time.perf_counter())
        with self.client.atomic():
            if poser is not None:
                self.scene.set_segment(poser, earlier)
                self.player.load(poser.n_frames)
            else:
                self.player.unload()
                self.scene.hide()
            self.panels.show_segment(info, segment.error)
        self.client.flush()
        with self._lock:  # time-per-label and the dwell count from the first frame sent
            segment.appeared = time.perf_counter()
        self.on_show(self, segment.key)
        # what follows is context, sent after the first frame is out
        if poser is not None:
            self.screen.show_floor(run, task, np.asarray(query.xy, float))
        self.screen.show_task(run, task)
        self.panels.show_inset(render_inset(task, np.asarray(query.xy, float), earlier))
        self._preload()
        self._show_progress()

    def _preload(self) -> None:
        """Claim the segment after the one on screen and prepare it, so the label key that ends
        this one shows the next at once. Best effort: without it the next is claimed on demand."""
        shown = self.state.shown
        if self.link is None or shown is None or not self.state.wants_preload(self.config.prefetch):
            return
        claimed, self._next_claim = self._next_claim, None
        try:
            if claimed is None or claimed.query.query_id == shown.query.query_id:
                claimed = self.link.claim(shown.run.id, hold=MAX_HOLD)
        except (Rejected, ServiceDown) as exc:
            log.info("no preload for run %s: %s", shown.run.id, exc)
            return
        if claimed is None or (shown.run.id, claimed.query.query_id) in self.state.moved:
            return
        if claimed.query.query_id != shown.query.query_id:
            segment = self._prepare(shown.run, claimed.query)
            with self._lock:
                self.state.preloaded(segment)

    def _show_progress(self) -> None:
        shown = self.state.shown
        if self.link is not None and shown is not None:
            progress = self.link.progress(shown.run.id, shown.query.session)
            self.panels.show_progress(progress)
            self.panels.show_instructions(progress.instructions)  # an operator may have changed them
            self._load_mine(shown.run)

    def _load_mine(self, run: RunRead) -> None:
        assert self.link is not None
        self.mine = self.link.my_labels(run.id)
        task = self.screen.task_of(run)
        self.panels.show_mine(self.mine, lambda label: render_inset(task, np.asarray(label.xy, float), None))

    def _renew(self) -> None:
        """Keep the claims alive while the labeler watches (a claim renews every lease one holds);
        a segment whose lease was lost meanwhile (this tab stalled past it) is dropped."""
        shown = self.state.shown
        if self.link is None or shown is None:
            return
        try:
            claimed = self.link.claim(shown.run.id)
        except Rejected as exc:
            self.panels.notify("Run closed", str(exc), "orange")
            with self._lock:
                self.state.leases(shown.run.id, set())
            return
        with self._lock:
            lost = self.state.leases(shown.run.id, set(claimed.held) if claimed is not None else set())
        if shown in lost:
            self.panels.notify("Claim lost", f"segment {shown.query.query_id} went to someone else", "orange")
            self._show_next(shown.run)

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
            ack = self.link.submit(run_id, query_id, value, seconds, request_id, segment.revising, self.config.prefetch)
            self._next_claim = ack.next  # what to preload, claimed with the label (one round trip, one commit)
        except Rejected as exc:
            reason = str(exc)
        with self._lock:
            if reason is None:
                self.state.recorded(submit)
            else:
                self.state.refused(submit)
        if reason is not None:
            self.panels.notify("Not recorded", reason, "red")
        self._show_next(segment.run)
        self._next_claim = None
        shown = self.state.shown
        if shown is not None and shown.appeared is not None and reason is None:
            self.timings.append({"query_id": shown.query.query_id, "key_to_frame_s": shown.appeared - at})

    def _undo(self, request_id: str) -> None:
        mine = [(m.run_id, m.query_id) for m in self.mine if m.in_effect]
        with self._lock:
            decision = self.state.undo_target(mine, request_id)
        if isinstance(decision, Refusal):
            self.panels.notify(decision.title, decision.body, "gray")
        elif isinstance(decision, Withdraw):
            self._withdraw(decision)

    def _withdraw(self, withdraw: Withdraw) -> None:
        assert self.link is not None
        try:
            self.link.undo(withdraw.run_id, withdraw.query_id, withdraw.request_id)
        except Rejected as exc:
            with self._lock:
                self.state.labelled = [k for k in self.state.labelled if k != (withdraw.run_id, withdraw.query_id)]
            self.panels.notify("Cannot undo", str(exc), "red")
            return
        run = self.link.run(withdraw.run_id)
        segment = self._prepare(run, self.link.query(withdraw.run_id, withdraw.query_id))
        with self._lock:
            self.state.withdrawn(withdraw, segment)
        self.player.pause()
        self.panels.notify("Label withdrawn", f"segment {withdraw.query_id} is back: label it again", "blue")
        self._show_next(run)

    def _relabel(self, query_id: str) -> None:
        """Replay one of this labeler's labelled segments; a label on it is a revision."""
        assert self.link is not None
        picked = next((m for m in self.mine if m.query_id == query_id), None)
        if picked is None:
            self.panels.notify("Not yours", f"segment {query_id} is not among your labels", "orange")
            return
        run = self.link.run(picked.run_id)
        segment = self._prepare(run, self.link.query(picked.run_id, query_id))
        segment.revising = True
        with self._lock:
            self.state.held.discard(segment.key)  # a revision needs no lease
            shown = self.state.shown
            if shown is not None and shown.key != segment.key:
                self.state.ahead.insert(0, shown)
        self._present(segment)

    def _recovered(self) -> None:
        down_since, self._down_since = self._down_since, None
        shown = self.state.shown
        if shown is not None and down_since is not None and (shown.appeared or 0.0) < down_since:
            self._present(shown)  # the outage screen hid it; show it again

    def _release_all(self) -> None:
        """Hand every claim this tab holds back to the pool (a closed tab, a sign-out); claims that
        another tab of this labeler took over were removed from this tab's by taken_over."""
        link = self.link
        with self._lock:
            keys = self.state.release_all()
        for run_id, query_id in keys:
            if link is not None:
                with contextlib.suppress(Rejected, ServiceDown, AuthRefused):  # else the lease runs out
                    link.release(run_id, query_id)

    # ---------------------------------------------------------------- the stream waiter

    def watch_stream(self, run_id: int, after: int) -> None:
        """Watch mode and the waiting screen's skills: wake the worker on the run's next event."""
        self._stream = (run_id, after)

    def _await_stream(self) -> None:
        while not self._closed.is_set():
            target, link = self._stream, self.stream_link
            if target is None or link is None:
                self._closed.wait(0.25)
                continue
            try:
                page = link.wait_for_events(target[0], target[1], self.config.wait_s)
            except (ServiceDown, AuthRefused, Rejected):
                self._closed.wait(1.0)
                continue
            except Exception:  # the link was closed under us (sign-out)
                self._closed.wait(0.25)
                continue
            if page.last_id > target[1] and self._stream == target:
                self._stream = (target[0], page.last_id)
                self._actions.put(Wake(frozenset(e.kind for e in page.events)))
