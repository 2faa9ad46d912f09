"""The labeling UI server: one viser server, one LabelerSession per connected browser tab.

viser runs its own websocket/HTTP server thread on its own port (it cannot be mounted inside
FastAPI); with port 0 the OS picks a free port, which `port` reads back.
"""

from __future__ import annotations

import threading
from urllib.parse import quote

import viser

from collie.addresses import link_host
from collie.mjmodels import MODEL_NAMES
from collie.startup import mark
from labeling_ui.browser import new_tab_id
from labeling_ui.models import warm_models
from labeling_ui.scene import south_view
from labeling_ui.session import LabelerSession, UiConfig
from labeling_ui.sibling_tabs import TabMemory
from labeling_ui.tab import Key

PROBE_S = 3.0  # a page that does not answer a round trip this fast counts as open (see tab_id)


class LabelingApp:  # SiblingTabs for its sessions
    def __init__(
        self, config: UiConfig, host: str = "127.0.0.1", port: int = 8090, warm: tuple[str, ...] = MODEL_NAMES
    ) -> None:
        self.config = config
        self.host = host
        self.server = viser.ViserServer(host=host, port=port, label="collie labeling", verbose=False)
        self.server.gui.set_panel_label("collie labeling")
        # the replayed robot always sits at the origin (the world moves under it)
        self.server.initial_camera.up = (0.0, 0.0, 1.0)
        self.server.initial_camera.position = south_view()  # as a segment aims it: no jump when it loads
        self.server.initial_camera.look_at = (0.0, 0.0, 0.0)
        self.sessions: dict[int, LabelerSession] = {}
        self.tab_memory: dict[str, TabMemory] = {}  # each browser tab's signed-in name and labels, across reloads
        self._tabs: dict[str, LabelerSession] = {}  # each tab id → the connection that goes by it
        self._closing: list[LabelerSession] = []  # closed tabs still in their grace period
        self._lock = threading.Lock()
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)
        self.compile_s: dict[str, float] = {}  # env → seconds its model took to compile, once warm
        self._warm_envs = warm  # compiled ahead of the first tab; the others on first use
        self._stopping = threading.Event()
        self._warm = threading.Thread(target=self._warm_models, name="collie-warm")
        self._warm.start()

    def _warm_models(self) -> None:
        self.compile_s.update(warm_models(self._warm_envs, stop=self._stopping))
        mark("models compiled")

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        return f"http://{link_host(self.host)}:{self.port}/"

    def labeler_url(self, token: str) -> str:
        """The link to hand a labeler: it signs them in with their token."""
        return f"{self.url}?token={quote(token, safe='')}"

    def _connect(self, client: viser.ClientHandle) -> None:
        session = LabelerSession(client, self.config, self)
        with self._lock:
            self.sessions[client.client_id] = session
        session.start()

    # ---------------------------------------------------------------- SiblingTabs (sibling_tabs.py)

    def _siblings(self, of: LabelerSession) -> list[LabelerSession]:
        """The other tabs of `of`'s labeler: open ones, and closed ones still in their grace period."""
        with self._lock:
            self._closing = [s for s in self._closing if not s.finished]
            others = [s for s in [*self.sessions.values(), *self._closing] if s is not of]
        return [s for s in others if s.who is not None and s.who == of.who]

    def shown(self, session: LabelerSession, key: Key) -> None:
        """Tabs of one labeler that go by one id hold the same leases at the service (a reload and
        the connection it replaced, a tab sharing another's id): the newest to show a segment is the
        one that labels it; the others must no longer label or release it."""
        for other in self._siblings(session):
            if key in other.on_screen_or_held():
                other.taken_over(key)

    def preloaded(self, session: LabelerSession, key: Key) -> None:
        for other in self._siblings(session):
            if other.closed.is_set() and key in other.on_screen_or_held():
                other.taken_over(key)

    def done(self, session: LabelerSession, key: Key, skipped: bool) -> None:
        for other in self._siblings(session):
            if key in other.on_screen_or_held():
                other.taken_over(key, "skipped" if skipped else "labelled")

    def released(self, session: LabelerSession, keys: list[Key]) -> None:
        if keys:
            for other in self._siblings(session):
                other.handed_back(keys)

    def tab_id(self, session: LabelerSession, tab: str) -> str:
        """The id `session` goes by: `tab`, the one its page keeps in sessionStorage, unless another
        open page goes by it. A tab the browser duplicates (or opens with window.open) starts with a
        copy of that sessionStorage, id included, and the service keeps claims per tab id: the copy
        gets an id of its own, and the original keeps its segments. A reload's old connection may
        still be open a moment after its page went, so the other connection's page is asked first:
        only one that answers makes this tab a copy (a reload keeps its id and gets its segment back)."""
        while True:
            with self._lock:
                holder = self._tabs.get(tab)
                # the same page come back (a network blip): its old connection may look open for a while
                again = holder is not None and holder.page is not None and holder.page == session.page
                if holder is None or holder is session or holder.closed.is_set() or again:
                    self._tabs[tab] = session
                    return tab
            if holder.page_open(PROBE_S):
                tab = new_tab_id()  # taken under the lock above on the next turn
                continue
            with self._lock:  # its page is gone: this is that tab, reloaded or reconnected
                if self._tabs.get(tab) is holder:
                    self._tabs[tab] = session
                    return tab

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            session = self.sessions.pop(client.client_id, None)
            if session is not None:
                self._closing.append(session)
                self._tabs = {tab: s for tab, s in self._tabs.items() if s is not session}
        if session is not None:
            session.close()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Close every tab's session (each hands its claims back), then the server."""
        self._stopping.set()  # the warm-up ends after the model it is compiling
        with self._lock:
            sessions = list(self.sessions.values())
            self.sessions.clear()
        for session in sessions:
            session.close(grace=False)
        for session in sessions:
            session.join(timeout_s / max(len(sessions), 1))
        self.server.stop()
        self._warm.join(30.0)  # exiting in the middle of a MuJoCo compile crashes the process
