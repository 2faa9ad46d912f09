"""What a tab's screen shows, state by state, on the tab's worker: a segment (first frame first,
its context after), the waiting screen with the run's forecast and the skills of its latest
evaluation, watch mode's skills, the outage screen, the labeler's progress and own labels, and the
labeler's playback settings. It draws through TabScreen and asks the service for what it shows."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from collie.schemas import FINISHED, RunRead
from labeling_ui.claims import Claims
from labeling_ui.guarded_tab import GuardedTab
from labeling_ui.inset import inset_caption, render_inset
from labeling_ui.models import ModelError, Poser
from labeling_ui.panels import APP_TITLE, SegmentInfo
from labeling_ui.review import show_review
from labeling_ui.screen import TabScreen
from labeling_ui.service import MyLabel, ServiceLink
from labeling_ui.stream_waiter import StreamWaiter, run_ended
from labeling_ui.tab import Key, Segment
from labeling_ui.waiting import EpochClock, forecast, waiting_text
from labeling_ui.watch import SkillShow


class Presenter:
    def __init__(
        self,
        tab: GuardedTab,
        screen: TabScreen,
        claims: Claims,
        waiter: StreamWaiter,
        fps: float,
        wait_s: float,
        on_show: Callable[[Key], None],
    ) -> None:
        """`on_show(key)`: a segment's first frame is out (the app takes it off this labeler's other tabs)."""
        self.tab, self.screen, self.claims, self.waiter = tab, screen, claims, waiter
        self.panels, self.scene, self.player = screen.panels, screen.scene, screen.player
        self.fps, self.wait_s = fps, wait_s
        self.on_show = on_show
        self.loop = True  # the labeler's loop setting (the skills between segments use their own)
        self.epochs = EpochClock()
        # the labeler's labels in the shown run, newest first: replaced whole (the panels read it from viser's threads)
        self.mine: tuple[MyLabel, ...] = ()
        self.skills: SkillShow | None = None
        self.reviewed: Key | None = None  # the query review mode shows (or said it cannot)

    # ---------------------------------------------------------------- a segment

    def show_next(self, link: ServiceLink, run: RunRead | None = None) -> bool:
        """Show the next segment (the prepared one, else a fresh claim in `run`, else in the run the
        service picks); False (and the waiting screen) when there is none, or the page went."""
        with self.tab as state:
            if state.closed:
                return False
            ready = state.next_ready()
        if ready is not None:
            return self.present(link, ready) or self.show_next(link, run)
        claim = self.claims.claim(link, run) if run is not None else None
        if claim is None:
            picked = link.pick_run()
            if picked is None:  # none open: how the run just shown ended, else that none takes labels now
                refused = self.claims.refused if run is not None else None  # (an earlier run's refusal is stale)
                self.wait_for(link, run, None if run else "No run on the service takes labels now.", refused)
                return False
            run = picked
            claim = self.claims.claim(link, run)
        if claim is None:
            self.wait_for(link, run, None, refused=self.claims.refused)
            return False
        # taken over by another tab while it was prepared: claim again (that one is never handed out here)
        return self.present(link, self.claims.prepare(*claim)) or self.show_next(link, run)

    def present(self, link: ServiceLink, segment: Segment) -> bool:
        """Show `segment`; False when another tab of this labeler took it over since it was claimed."""
        run, query = segment.run, segment.query
        poser: Poser | None = segment.replay
        if poser is not None:
            try:
                self.scene.load(run.env)  # builds the robot when the env changes
            except ModelError as exc:
                poser, segment.error, segment.replay = None, str(exc), None
        self.skills = None
        self.waiter.follow(run.id, run.last_event_id, run_ended)  # a stop, said while the segment is on screen
        self.player.fps = self.fps
        if self.player.loop != self.loop:  # the skills shown while waiting may have changed it
            self.player.loop = self.loop
            self.panels.loop.value = self.loop  # type: ignore[misc]  # viser types .value read-only; it is settable
        task = self.screen.task_of(run)
        info = SegmentInfo(
            query.query_id, run.id, run.env, run.task, run.method, query.epoch, query.session, query.start,
            query.skill, len(query.qpos), segment.revising,
        )  # fmt: skip
        earlier = np.asarray(query.path_xy, float)[: query.start + 1] if query.path_xy else None
        with self.tab as state:  # keys from now on apply to this segment
            if not state.present(segment, time.perf_counter()):
                return False
            again = segment.key in state.skipped and not segment.revising
        if again:  # the queue came round: say so, or it looks like the skip did nothing
            back = f"{query.query_id} is back: the others are labelled or skipped"
            self.panels.notify("Skipped before", back, "gray")
        with self.screen.client.atomic():
            if poser is not None:
                self.scene.set_segment(poser, earlier)
                self.player.load(poser.n_frames)
            else:
                self.screen.blank()
            self.panels.show_segment(info, segment.error)
        self.screen.client.flush()
        with self.tab:  # time-per-label and the dwell count from the first frame sent
            segment.appeared = time.perf_counter()
        self.on_show(segment.key)
        # what follows is context, sent after the first frame is out
        if poser is not None:
            self.screen.show_floor(run, task, np.asarray(query.xy, float))
        self.screen.show_task(run, task)
        xy = np.asarray(query.xy, float)
        self.panels.show_inset(render_inset(task, xy, earlier), inset_caption(xy, earlier))
        self.claims.preload(link)
        self.show_progress(link)
        return True

    def show_progress(self, link: ServiceLink, mine: bool = True) -> None:
        """The session's and the run's counts, and the operator's instructions, as they are now;
        `mine`: the labeler's own labels too (a read and an inset each)."""
        with self.tab as state:
            shown = state.shown
        if shown is not None:
            progress = link.progress(shown.run.id, shown.query.session)
            if mine:
                self.load_mine(link, shown.run)
            yours = sum(1 for label in self.mine if label.session == shown.query.session and label.in_effect)
            self.panels.show_progress(progress, yours)
            self.panels.show_instructions(progress.instructions)  # an operator may have changed them

    def load_mine(self, link: ServiceLink, run: RunRead) -> None:
        self.mine = tuple(link.my_labels(run.id))
        task = self.screen.task_of(run)
        self.panels.show_mine(self.mine, lambda label: render_inset(task, np.asarray(label.xy, float), None))

    # ---------------------------------------------------------------- nothing to label

    def wait_for(self, link: ServiceLink, run: RunRead | None, status: str | None, refused: str | None = None) -> None:
        """Nothing claimable in `run` (None: no run is open; `status` says so); `refused`: the
        service's reason, when it refused the claim (e.g. this labeler's other tabs hold enough)."""
        since = run.last_event_id if run is not None else None  # as read before the claim, maybe long before
        run = link.run(run.id) if run is not None else None  # fresh counts, after our own claims
        with self.tab as state:
            state.nothing_claimable(run, time.monotonic(), self.wait_s, since)
            held_here = state.held_in(run.id) if run is not None else 0
            waiting_on = state.waiting_on
        if waiting_on is None:
            self.waiter.stop_following()
        else:
            self.waiter.follow(*waiting_on)
        ended = run is not None and (run.status in FINISHED or run.control == "stop")
        if run is not None:
            seen = self.epochs.rate(run, time.monotonic())
            status = waiting_text(run, forecast(run, link.metrics(run.id), seen), held_here)
            self.load_mine(link, run)
        if refused and not ended:  # an ended run's state says it in our words ("stopped", not "finished")
            status = f"⚠️ The service said: {refused}  \n{status or ''}"
        skills = self.skills
        keep = skills is not None and run is not None and skills.run_id == run.id
        self.show_waiting(status or "", keep_skills=keep, ended=ended)

    def show_waiting(self, status: str, keep_skills: bool = False, ended: bool = False) -> None:
        """The waiting screen; the skills of the run's latest evaluation keep playing if they are on.
        `ended`: the run takes no more labels, so no segment will come."""
        if not keep_skills:
            self.skills = None
            self.screen.blank()
        # an ended run: no "right now" and no undo, as nothing more comes and the service takes no undo
        head, after, title = (
            ("🏁 **Nothing more to label in this run.**", "This run takes no more labels; yours are kept.", "Run over")
            if ended
            else ("☕ **Nothing to label right now.**", "New segments appear here by themselves.", "Waiting")
        )
        self.panels.show_message(
            f"{head}  \n{status}  \n{after}", keep_replay=keep_skills, title=f"{title} · {APP_TITLE}", undo=not ended
        )

    def play_skills(self, link: ServiceLink, run_id: int, watching: bool) -> None:
        """The run's latest skills play in 3D (watch mode's own screen, or the waiting screen's view)."""
        if self.skills is None or self.skills.run_id != run_id:
            self.skills = SkillShow(self.screen, run_id, self.fps, self.waiter.follow if watching else None)
            self.skills.reload(link)
        self.skills.tick()

    def review(self, link: ServiceLink, key: Key, role: str | None) -> None:
        """Review mode: replay the query `key` with its labels, once (it then loops by itself)."""
        if self.reviewed != key:
            show_review(self.screen, link, role, *key)
            self.reviewed = key

    def new_rollouts(self, link: ServiceLink) -> None:
        if self.skills is not None:
            self.skills.reload(link)

    def show_outage(self, why: str, retry_s: float, signed_in: bool = True) -> None:
        """`signed_in`: False while the token is being checked (then no labeling control shows)."""
        self.player.pause()
        self.scene.hide()
        said = f"⚠️ **The labeling service is unreachable** ({why}).  \nRetrying in {retry_s:.0f} s… "
        if signed_in:
            self.panels.show_message(said + "nothing you labelled is lost.")
        else:
            self.panels.show_checking(said + "your token is checked once it answers.")

    def clear(self) -> None:
        """Signed out: nothing of the last identity stays on screen."""
        self.skills = None
        self.reviewed = None
        self.mine = ()
        self.screen.blank()

    # ---------------------------------------------------------------- the labeler's playback settings

    def use_prefs(self, prefs: dict[str, object]) -> None:
        speed, loop = prefs.get("speed"), prefs.get("loop")
        if isinstance(speed, int | float):
            self.player.set_speed(float(speed))
        if isinstance(loop, bool):
            self.loop = self.player.loop = loop
            self.panels.loop.value = loop  # type: ignore[misc]  # viser types .value read-only; it is settable
        self.panels.show_speed(self.player.speed)

    def prefs(self) -> dict[str, object]:
        return {"speed": self.player.speed, "loop": self.loop}
