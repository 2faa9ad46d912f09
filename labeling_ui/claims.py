"""A tab's claims on the service: claiming a segment (and the one after it, preloaded while one is
on screen), preparing it to show, renewing the leases while the labeler watches, and handing them
back (a sign-out, a closed tab after its grace period). Runs on the tab's worker; the decisions
(which claims this tab may show, which it lost) are the state machine's (tab.py)."""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable

import numpy as np

from collie.schemas import FINISHED, MAX_HOLD, ClaimRead, QueryRead, RunRead
from labeling_ui.guarded_tab import GuardedTab
from labeling_ui.models import ModelError, Poser, replay_model
from labeling_ui.screen import TabScreen
from labeling_ui.service import AuthRefused, Rejected, ServiceDown, ServiceLink
from labeling_ui.tab import Key, Segment
from labeling_ui.waiting import ended_words

log = logging.getLogger(__name__)


class Claims:
    def __init__(
        self, tab: GuardedTab, screen: TabScreen, prefetch: bool, on_hold: Callable[[Key], None] = lambda _: None
    ) -> None:
        """`on_hold(key)`: a preloaded segment is this tab's to show next (the app takes it off the
        labeler's other tabs: the connection a reload replaced would hand it back after its grace)."""
        self.tab = tab
        self.on_hold = on_hold
        self.screen = screen
        self.prefetch = prefetch  # claim and prepare the next segment while one is on screen
        self.next_claim: ClaimRead | None = None  # the preload a label's answer carried (used once)
        self.refused: str | None = None  # why the last claim was refused (a run that ended, a tab too many)

    def claim(self, link: ServiceLink, run: RunRead) -> tuple[RunRead, QueryRead] | None:
        """A segment this tab may show: a fresh claim, or one this labeler holds that no other of
        its tabs shows (the service keeps claims per labeler)."""
        self.refused = None
        for hold in (1, MAX_HOLD):
            try:
                claimed = link.claim(run.id, hold=hold)
            except Rejected as exc:  # the run stopped or finished meanwhile, or this is a tab too many
                self.refused = str(exc)
                return None
            if claimed is None:
                return None
            with self.tab as state:
                if state.may_show((run.id, claimed.query.query_id)):
                    return run, claimed.query
        return None  # both of this labeler's claims are on screen in other tabs

    def prepare(self, run: RunRead, query: QueryRead) -> Segment:
        """A claimed segment made ready to show: its model compiled and its frames checked."""
        with self.tab as state:
            state.claimed(Segment(run, query, None))
        task = self.screen.task_of(run)
        classes = (0, 1, 2) if task is None or task.can_be_good else (0, 1)
        try:
            poser = Poser(replay_model(run.env), np.asarray(query.qpos, float))
            return Segment(run, query, poser, classes=classes)
        except ModelError as exc:
            return Segment(run, query, None, str(exc), classes=classes)

    def preload(self, link: ServiceLink) -> None:
        """Claim the segment after the one on screen and prepare it, so the label key that ends
        this one shows the next at once. Best effort: without it the next is claimed on demand."""
        with self.tab as state:
            shown = state.shown
            wanted = shown is not None and state.wants_preload(self.prefetch)
        if shown is None or not wanted:
            return
        claimed, self.next_claim = self.next_claim, None
        try:
            if claimed is None or claimed.query.query_id == shown.query.query_id:
                claimed = link.claim(shown.run.id, hold=MAX_HOLD)
        except (Rejected, ServiceDown) as exc:
            log.info("no preload for run %s: %s", shown.run.id, exc)
            return
        if claimed is None:
            return
        with self.tab as state:
            usable = state.may_show((shown.run.id, claimed.query.query_id))
        if usable and claimed.query.query_id != shown.query.query_id:
            segment = self.prepare(shown.run, claimed.query)
            with self.tab as state:
                kept = state.preloaded(segment)
            if kept:
                self.on_hold(segment.key)

    def renew(self, link: ServiceLink) -> Segment | None:
        """Keep the claims alive while the labeler watches (a claim renews every lease this tab holds).
        Returns the segment on screen if its lease was lost meanwhile (this tab stalled past it) or its
        run ended: it is dropped (with what was preloaded of that run), and the caller shows the next."""
        with self.tab as state:
            shown = state.shown
        if shown is None:
            return None
        try:
            claimed = link.claim(shown.run.id)
        except Rejected as exc:  # the run ended, or this labeler may no longer label it: nothing of it stays
            words = self.ended(link, shown.run.id)
            self.screen.panels.notify("Run closed", words or str(exc), "orange")
            with self.tab as state:
                state.leases(shown.run.id, set())
            return shown
        with self.tab as state:
            lost = state.leases(shown.run.id, set(claimed.held) if claimed is not None else set())
        if shown not in lost:
            return None
        self.screen.panels.notify("Claim lost", f"segment {shown.query.query_id} went to someone else", "orange")
        return shown

    def ended(self, link: ServiceLink, run_id: int) -> str | None:
        """If `run_id` ended (an operator stopped it, or it finished): its segments leave this tab,
        preloaded ones too, and the words that say so ("stopped", never "finished" for a stop)."""
        try:
            run = link.run(run_id)
        except Rejected:
            return None
        if run.status not in FINISHED and run.control != "stop":
            return None
        with self.tab as state:
            state.leases(run_id, set())
        return ended_words(run)

    def release_all(self, link: ServiceLink | None) -> list[Key]:
        """Hand every claim this tab holds back to the pool (a closed tab, a sign-out); claims that
        another tab of this labeler took over were removed from this tab's by taken_over. Returns
        the keys handed back (a release the service did not answer leaves its lease to run out)."""
        with self.tab as state:
            keys = state.release_all()
        released = []
        for run_id, query_id in keys:
            if link is not None:
                with contextlib.suppress(Rejected, ServiceDown, AuthRefused):
                    link.release(run_id, query_id)
                    released.append((run_id, query_id))
        return released

    def release_on_close(self, link: ServiceLink | None, grace_s: float) -> list[Key]:
        """The tab closed: after `grace_s` (a reload of the tab picks its claims up again meanwhile,
        and the new tab's on_show takes them off this one), hand back what is still held."""
        with self.tab as state:
            holding = bool(state.held)
        if grace_s > 0 and holding:
            time.sleep(grace_s)
        return self.release_all(link)
