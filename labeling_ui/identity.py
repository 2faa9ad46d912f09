"""A tab's identity on the service: the token it signs in with, the two links that token opens
(the worker's, and the stream waiter's for its long polls), who the service says the token is,
and signing out (a sign-out, or a refused token: this tab only, its own sessionStorage). Runs on
the tab's worker."""

from __future__ import annotations

import viser

from labeling_ui.actions import UiConfig
from labeling_ui.browser import load_prefs, remember_token
from labeling_ui.claims import Claims
from labeling_ui.guarded_tab import GuardedTab
from labeling_ui.presenter import Presenter
from labeling_ui.service import ServiceLink
from labeling_ui.sibling_tabs import TabMemory
from labeling_ui.stream_waiter import StreamWaiter


class Identity:
    def __init__(
        self,
        client: viser.ClientHandle,
        config: UiConfig,
        tab: GuardedTab,
        claims: Claims,
        presenter: Presenter,
        waiter: StreamWaiter,
    ) -> None:
        self.client, self.config, self.tab = client, config, tab
        self.claims, self.presenter, self.waiter = claims, presenter, waiter
        self.panels = presenter.panels
        self.link: ServiceLink | None = None  # the worker's; None while signed out
        self.stream_link: ServiceLink | None = None  # the stream waiter's
        self.tab_id: str | None = None  # the browser tab's id: claims and labels name it
        self.memory: TabMemory | None = None  # what the app keeps of this tab across reloads

    def use_token(self, token: str) -> None:
        self.claims.release_all(self.link)
        self._stop_links()
        if not token:
            self.panels.show_login("Type a token first.")
            return
        with self.tab as state:
            state.use_token(token)
        self.panels.show_checking("Checking your token…")
        self.link = ServiceLink(self.config.api, token, self.config.run_id, self.config.lease_s, self.tab_id)
        self.stream_link = ServiceLink(self.config.api, token, self.config.run_id, self.config.lease_s, self.tab_id)
        self.waiter.use(self.stream_link)
        remember_token(self.client, token)

    def check_token(self) -> None:
        """Ask the service whose token it is; greet them, loudly if this tab was someone else."""
        assert self.link is not None
        me = self.link.login()
        with self.tab as state:
            before = state.accepted(me.name, me.role)
            watching = state.replay_only
        if self.memory is not None:  # a reload of this tab knows who labelled here
            self.memory.who = me.name
        self.panels.greet(me.name, me.role, before, labels=not watching)
        if before is not None:  # loud: this tab was someone else a moment ago
            self.panels.notify("You are now " + me.name, f"this tab was signed in as {before}", "red")
        self.presenter.use_prefs(load_prefs(self.client, me.name) if not watching else {})
        if not watching:
            self.panels.show_message("Looking for segments to label…")

    def sign_out(self, message: str) -> None:
        """Hand the claims back, forget the token, and show the sign-in field with `message`."""
        self.claims.release_all(self.link)
        remember_token(self.client, None)
        self._stop_links()
        with self.tab as state:
            state.signed_out()
        self.panels.show_login(message)

    def _stop_links(self) -> None:
        self.waiter.use(None)
        self.waiter.stop_following()
        for link in (self.link, self.stream_link):
            if link is not None:
                link.close()
        self.link = self.stream_link = None
        self.presenter.clear()
