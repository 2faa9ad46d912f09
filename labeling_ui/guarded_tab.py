"""A tab's state machine shared by viser's callback threads, the tab's worker and the app (another
tab taking a segment over): every read and write of it goes through one lock, `with tab as state:`.

The player thread is the one exception: it is the only writer of the shown segment's `played_to`
(TabState.frame_drawn, a float the key handler reads under the lock)."""

from __future__ import annotations

import threading

from labeling_ui.tab import TabState


class GuardedTab:
    def __init__(self, state: TabState) -> None:
        self.unguarded = state  # for the player's frame_drawn, and for tests that poll it
        self._lock = threading.Lock()

    def __enter__(self) -> TabState:
        self._lock.acquire()
        return self.unguarded

    def __exit__(self, *_: object) -> None:
        self._lock.release()
