"""One browser tab's labeling session: sign in, claim, replay, label / skip / undo, wait for work,
and the error screens.

GUI callbacks only enqueue; one worker thread talks to the service in order, so a fast labeler's
keys are handled one at a time, each against the segment that was on screen when it was pressed.
While a segment is on screen the next one is already claimed and prepared (the service lets a
labeler hold two), so a label key shows the next segment without a round trip.
While nothing is claimable, a watcher thread long-polls the run's event stream and wakes the
worker when something happens, so new queries appear without a reload.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import viser

from collie.client import new_request_id
from collie.labels import Label
from collie.schemas import MAX_HOLD, QueryRead, RunRead
from collie.tasks import Task, get_task
from labeling_ui.browser import read_token, read_watch, remember_token
from labeling_ui.inset import render_inset
from labeling_ui.keys import bind_keys
from labeling_ui.models import ModelError, Poser, replay_model
from labeling_ui.panels import Panels, SegmentInfo
from labeling_ui.playback import Player
from labeling_ui.regions import tint_grid, tint_meshes
from labeling_ui.scene import ReplayScene
from labeling_ui.service import AuthRefused, Rejected, ServiceDown, ServiceLink
from labeling_ui.watch import SkillWatch

log = logging.getLogger(__name__)

HISTORY = 50  # labels that `undo` can walk back, newest last
FLOOR_HALF_WIDTH = 20.0  # the region tint on the 3D floor spans this far around the segment...
FLOOR_SNAP = 10.0  # ...whose centre snaps to this grid, so nearby segments share one tint


@dataclass(frozen=True)
class UiConfig:
    api: str
    run_id: int | None = None  # pin one run; else the newest open run with work
    lease_s: float = 60.0  # renewed while the tab is open; a crashed UI frees its claim this fast
    fps: float = 20.0  # segment frames per second at 1× (env steps are 0.05 s)
    min_dwell_s: float = 0.3  # label keys are ignored this long after a segment appears
    prefetch: bool = True  # claim and prepare the next segment while one is on screen
    wait_s: float = 10.0  # long-poll length while waiting for work
    release_grace_s: float = 5.0  # a closed tab's claims wait this long for a reload of it
    retry_max_s: float = 5.0


@dataclass
class Shown:
    run: RunRead
    query: QueryRead
    poser: Poser | None
    error: str | None
    appeared: float = 0.0  # perf_counter() when its first frame was sent


@dataclass(frozen=True)
class Action:
    kind: str  # sign_in, sign_out, label, skip, undo, wake, close
    value: Any = None
    query_id: str | None = None
    at: float = field(default_factory=time.perf_counter)
    request_id: str = field(default_factory=new_request_id)


class LabelerSession:
    """Implements panels.Actions for one viser client."""

    def __init__(
        self,
        client: viser.ClientHandle,
        config: UiConfig,
        held_elsewhere: Callable[[LabelerSession, int, str], bool] = lambda *_: False,
    ) -> None:
        self.client = client
        self.config = config
        self.held_elsewhere = held_elsewhere  # is (run, query) now on screen in another of our tabs?
        self._grace = True
        self.panels = Panels(client, self)
        bind_keys(client, self)
        self.scene = ReplayScene(client)
        self.player = Player(self.scene.show, self.panels.show_frame, fps=config.fps)
        self.link: ServiceLink | None = None
        self.watch_link: ServiceLink | None = None
        self.signed_in = False
        self.shown: Shown | None = None
        self.held: set[tuple[int, str]] = set()  # (run, query) leases this tab holds
        self.ahead: list[Shown] = []  # claimed and prepared, shown next (a preload, an undo's interrupted one)
        self.history: list[Shown] = []
        self.waiting_on: tuple[int, int] | None = None  # (run, last event id) while idle
        self.timings: list[dict[str, float | str]] = []  # key → next first frame, for benchmarks
        self.watch_run: int | None = None  # ?watch=RUN: replay that run's skills instead of labeling
        self._skills: SkillWatch | None = None
        self._actions: queue.Queue[Action] = queue.Queue()
        self._retry: Action | None = None
        self._down_since: float | None = None
        self._closed = threading.Event()
        self._tasks: dict[tuple[str, str, object], Task | None] = {}
        self._worker = threading.Thread(target=self._work, name=f"collie-labeler-{client.client_id}", daemon=True)
        self._watcher = threading.Thread(target=self._watch, name=f"collie-watch-{client.client_id}", daemon=True)

    @property
    def token(self) -> str | None:
        return self.link.client.token if self.link is not None else None

    @property
    def closed(self) -> threading.Event:
        return self._closed

    def start(self) -> LabelerSession:
        self._worker.start()
        self._watcher.start()
        return self

    def close(self, grace: bool = True) -> None:
        """The tab went away: stop, and hand back any claim (done by the worker on its way out,
        after a grace period in which a reload of the tab picks its claim up again)."""
        self._grace = grace
        self._closed.set()
        self._actions.put(Action("close"))
        self.player.close()

    def join(self, timeout_s: float) -> None:
        if self._worker.is_alive():
            self._worker.join(timeout_s)

    # ---------------------------------------------------------------- Actions (GUI threads)

    def sign_in(self, token: str) -> None:
        self._actions.put(Action("sign_in", token))

    def sign_out(self) -> None:
        self._actions.put(Action("sign_out"))

    def label(self, value: Label) -> None:
        self._judge("label", value)

    def skip(self) -> None:
        self._judge("skip", "skip")

    def undo(self) -> None:
        self._actions.put(Action("undo"))

    def _judge(self, kind: str, value: int | str) -> None:
        shown = self.shown
        if shown is None:
            return
        if kind == "label" and shown.error is not None:
            self.panels.notify("Cannot label", "this segment cannot be replayed; press S to skip it", "orange")
            return
        if time.perf_counter() - shown.appeared < self.config.min_dwell_s:
            # a double tap or a held key must not label the segment that has only just appeared
            return
        self._actions.put(Action(kind, value, shown.query.query_id))

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

    def set_loop(self, loop: bool) -> None:
        self.player.loop = loop

    def set_shadows(self, on: bool) -> None:
        self.scene.set_shadows(on)

    # ---------------------------------------------------------------- the worker

    def _work(self) -> None:
        token = read_token(self.client)
        self.watch_run = read_watch(self.client)
        if token:
            self._start_link(token)
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
                self._waiting(f"The service said: {exc}")
                self._closed.wait(self.config.wait_s)
            except Exception as exc:  # keep the tab alive; say what happened
                log.exception("labeling session %s", self.client.client_id)
                self.panels.notify("Unexpected error", repr(exc)[:300], "red")
                self.shown = None
                self._closed.wait(1.0)
        if self._grace and self.held:
            time.sleep(self.config.release_grace_s)
        self._release_all()

    def _iterate(self) -> None:
        if self._retry is not None:  # an action the outage interrupted, same request id
            action, self._retry = self._retry, None
            self._handle(action)
            return
        if self.link is None:
            self._handle(self._actions.get())
            return
        if not self.signed_in:
            me = self.link.login()
            self.signed_in = True
            self.panels.greet(me.name)
            self.panels.show_message("Looking for segments to label…")
            return
        if self.watch_run is not None:
            self._skills = self._skills or SkillWatch(self, self.watch_run)
            self._skills.run()  # until the tab closes
            return
        if self.shown is None:
            if not self._claim_next():
                self._handle(self._next_action(self.config.wait_s))
            return
        waiting = self._next_action(self.config.lease_s / 3)
        if waiting is None:
            self._renew()
        else:
            self._handle(waiting)

    def _next_action(self, timeout_s: float) -> Action | None:
        try:
            return self._actions.get(timeout=timeout_s)
        except queue.Empty:
            return None

    def _handle(self, action: Action | None) -> None:
        if action is None or action.kind in ("wake", "close"):
            return
        try:
            if action.kind == "sign_in":
                self._start_link(str(action.value))
            elif action.kind == "sign_out":
                self._release_all()
                remember_token(self.client, None)
                self._stop_link()
                self.panels.show_login("Signed out. Paste a labeler token to sign in again.")
            elif self.link is None:
                return
            elif action.kind in ("label", "skip"):
                self._submit(action)
            elif action.kind == "undo":
                self._undo(action)
        except ServiceDown:
            self._retry = action
            raise

    # ---------------------------------------------------------------- signing in

    def _start_link(self, token: str) -> None:
        self._stop_link()
        if not token:
            self.panels.show_login("Type a token first.")
            return
        self.panels.show_message("Checking your token…")
        self.link = ServiceLink(self.config.api, token, self.config.run_id, self.config.lease_s)
        self.watch_link = ServiceLink(self.config.api, token, self.config.run_id, self.config.lease_s)
        remember_token(self.client, token)

    def _stop_link(self) -> None:
        for link in (self.link, self.watch_link):
            if link is not None:
                link.close()
        self.link = self.watch_link = None
        self.signed_in = False
        self.shown = None
        self.ahead.clear()
        self.waiting_on = None
        self.history.clear()
        self.player.unload()
        self.scene.hide()

    def _refused(self, detail: str) -> None:
        self._release_all()
        self._stop_link()
        remember_token(self.client, None)
        self.panels.show_login(f"⚠️ **The service refused this token**: {detail}  \nCheck it and sign in again.")

    # ---------------------------------------------------------------- claiming and showing

    def _claim_next(self, run: RunRead | None = None) -> bool:
        """Show the next segment (the preloaded one, else a fresh claim); False (and the waiting
        screen) when there is none."""
        assert self.link is not None
        if self.ahead:
            self.waiting_on = None
            self._present(self.ahead.pop(0))
            return True
        claim = None
        if run is not None:
            claim = self._claim(run)
        if claim is None:
            run = self.link.pick_run()
            if run is None:
                self.waiting_on = None
                self._waiting("No run is open on the service yet.")
                return False
            claim = self._claim(run)
        if claim is None:
            assert run is not None
            self.waiting_on = (run.id, run.last_event_id)
            self._waiting(self._run_status(run))
            return False
        self.waiting_on = None
        self._present(self._prepare(*claim))
        return True

    def _claim(self, run: RunRead) -> tuple[RunRead, QueryRead] | None:
        assert self.link is not None
        try:
            claimed = self.link.claim(run.id)
        except Rejected:  # the run stopped or finished meanwhile
            return None
        return None if claimed is None else (run, claimed.query)

    def _waiting(self, status: str) -> None:
        self.shown = None
        self.player.unload()
        self.scene.hide()
        self.panels.show_message(
            f"☕ **Nothing to label right now.**  \n{status}  \nNew segments appear here by themselves."
        )

    @staticmethod
    def _run_status(run: RunRead) -> str:
        q = run.queue
        words = run.status.replace("_", " ")
        return (
            f"Run {run.id} ({run.env}, {run.task}) is *{words}* at epoch {run.epoch}: "
            f"{q.leased} being labelled by others, {run.n_labels} labelled."
        )

    def _prepare(self, run: RunRead, query: QueryRead) -> Shown:
        """A claimed segment made ready to show: its model compiled and its frames checked."""
        self.held.add((run.id, query.query_id))
        try:
            return Shown(run, query, Poser(replay_model(run.env), np.asarray(query.qpos, float)), None)
        except ModelError as exc:
            return Shown(run, query, None, str(exc))

    def _present(self, item: Shown) -> None:
        run, query, poser, error = item.run, item.query, item.poser, item.error
        self.held.add((run.id, query.query_id))
        if poser is not None:
            try:
                self.scene.load(run.env)  # builds the robot when the env changes
            except ModelError as exc:
                poser, error = None, str(exc)
        task = self.task_of(run)
        info = SegmentInfo(
            query.query_id,
            run.id,
            run.env,
            run.task,
            run.method,
            query.epoch,
            query.session,
            query.start,
            query.skill,
            len(query.qpos),
        )
        earlier = None
        if query.path_xy:
            earlier = np.asarray(query.path_xy, float)[: query.start + 1]
        with self.client.atomic():
            if poser is not None:
                self.scene.set_segment(poser, earlier)
                self.player.load(poser.n_frames)
            else:
                self.player.unload()
                self.scene.hide()
            self.panels.show_segment(info, error)
        self.client.flush()
        self.shown = Shown(run, query, poser, error, appeared=time.perf_counter())
        # what follows is context, sent after the first frame is out
        if poser is not None:
            self.show_floor(run, task, np.asarray(query.xy, float))
        if task is not None:
            self.panels.show_task(task.name, task.description, task.meaning)
        else:
            self.panels.show_task(run.task, f"Unknown task '{run.task}' for {run.env}: judge by its name.", {})
        self.panels.show_inset(render_inset(task, np.asarray(query.xy, float), earlier))
        self._show_progress()
        self._preload()

    def _preload(self) -> None:
        """Claim the segment after the one on screen and prepare it, so the label key that ends
        this one shows the next at once. Best effort: without it the next is claimed on demand."""
        shown = self.shown
        if not self.config.prefetch or self.link is None or shown is None or self.ahead or len(self.held) >= MAX_HOLD:
            return
        try:
            claimed = self.link.claim(shown.run.id, hold=MAX_HOLD)
        except (Rejected, ServiceDown) as exc:
            log.info("no preload for run %s: %s", shown.run.id, exc)
            return
        if claimed is not None and claimed.query.query_id != shown.query.query_id:
            self.ahead.append(self._prepare(shown.run, claimed.query))

    def show_floor(self, run: RunRead, task: Task | None, xy: np.ndarray) -> None:
        """The task's regions on the floor around the segment, recomputed only when the segment
        leaves the area they cover (centres snap to a coarse grid)."""
        cx, cy = np.round(xy.mean(axis=0) / FLOOR_SNAP) * FLOOR_SNAP
        key = (run.task, run.env, cx, cy)
        if key == self.scene.floor_key:
            return
        tint = tint_meshes(task, cx, cy, FLOOR_HALF_WIDTH)
        self.scene.set_floor(key, task.to_dict() if task else None, tint, tint_grid(cx, cy, FLOOR_HALF_WIDTH))

    def task_of(self, run: RunRead) -> Task | None:
        key = (run.task, run.env, run.config.get("seed"))
        if key not in self._tasks:
            try:
                self._tasks[key] = get_task(run.task, run.env, layout_seed=run.config.get("seed"))
            except ValueError:
                self._tasks[key] = None
        return self._tasks[key]

    def _show_progress(self) -> None:
        if self.link is not None and self.shown is not None:
            self.panels.show_progress(self.link.progress(self.shown.run.id, self.shown.query.session))

    def _renew(self) -> None:
        """Keep the claims alive while the labeler watches (a claim renews every lease one holds);
        a segment whose lease was lost meanwhile (this tab stalled past it) is dropped."""
        shown = self.shown
        if self.link is None or shown is None:
            return
        try:
            claimed = self.link.claim(shown.run.id)
        except Rejected as exc:
            self.panels.notify("Run closed", str(exc), "orange")
            self.shown = None
            self.ahead.clear()
            return
        still = set(claimed.held) if claimed is not None else set()
        for item in [i for i in self.ahead if i.query.query_id not in still]:
            self.ahead.remove(item)
            self.held.discard((item.run.id, item.query.query_id))
        if shown.query.query_id not in still:
            self.held.discard((shown.run.id, shown.query.query_id))
            self.panels.notify("Claim lost", f"segment {shown.query.query_id} went to someone else", "orange")
            self.shown = None
            if claimed is not None and all(i.query.query_id != claimed.query.query_id for i in self.ahead):
                self.ahead.insert(0, self._prepare(shown.run, claimed.query))
            self._claim_next(shown.run)

    # ---------------------------------------------------------------- labels

    def _submit(self, action: Action) -> None:
        shown = self.shown
        if self.link is None or shown is None or shown.query.query_id != action.query_id:
            return  # a key pressed on a segment that is gone
        run_id, query_id = shown.run.id, shown.query.query_id
        seconds = max(0.0, action.at - shown.appeared)
        try:
            self.link.submit(run_id, query_id, action.value, seconds, action.request_id)
        except Rejected as exc:
            self.held.discard((run_id, query_id))
            self.shown = None
            self.panels.notify("Not recorded", str(exc), "red")
            return
        self.held.discard((run_id, query_id))
        if action.kind == "label":
            self.history = [*self.history[-(HISTORY - 1) :], shown]
        self.shown = None
        self._claim_next(shown.run)
        if self.shown is not None:
            self.timings.append(
                {"query_id": self.shown.query.query_id, "key_to_frame_s": self.shown.appeared - action.at}
            )

    def _undo(self, action: Action) -> None:
        assert self.link is not None
        if not self.history:
            self.panels.notify("Nothing to undo", "no label from this tab to take back", "gray")
            return
        last = self.history[-1]
        try:
            self.link.undo(last.run.id, last.query.query_id, action.request_id)
        except Rejected as exc:
            self.history.pop()
            self.panels.notify("Cannot undo", str(exc), "red")
            return
        self.history.pop()
        self.player.pause()
        self.panels.notify("Label withdrawn", f"segment {last.query.query_id} is back: label it again", "blue")
        if self.shown is not None and self.shown.query.query_id != last.query.query_id:
            self.ahead.insert(0, self.shown)  # it comes back after the relabel
        self._present(last)

    def _recovered(self) -> None:
        down_since, self._down_since = self._down_since, None
        shown = self.shown
        if shown is not None and down_since is not None and shown.appeared < down_since:
            self._present(shown)  # the outage screen hid it; show it again

    def _release_all(self) -> None:
        """Hand every claim this tab holds back to the pool (a closed tab, a sign-out)."""
        link = self.link
        for run_id, query_id in list(self.held):
            if link is not None and not self.held_elsewhere(self, run_id, query_id):
                with contextlib.suppress(Rejected, ServiceDown, AuthRefused):  # else the lease runs out
                    link.release(run_id, query_id)
        self.held.clear()
        self.ahead.clear()

    # ---------------------------------------------------------------- the watcher

    def _watch(self) -> None:
        while not self._closed.is_set():
            target, link = self.waiting_on, self.watch_link
            if target is None or link is None:
                self._closed.wait(0.25)
                continue
            try:
                last = link.wait_for_events(target[0], target[1], self.config.wait_s)
            except (ServiceDown, AuthRefused, Rejected):
                self._closed.wait(1.0)
                continue
            except Exception:  # the link was closed under us (sign-out)
                self._closed.wait(0.25)
                continue
            if last > target[1] and self.waiting_on == target:
                self.waiting_on = (target[0], last)
                self._actions.put(Action("wake"))
