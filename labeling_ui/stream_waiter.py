"""The tab's stream waiter: a thread that long-polls one run's event stream while the tab has
nothing to label (the waiting screen), watches a run (watch mode) or shows a segment (then only
the run's end wakes it), and wakes the tab's worker with what the stream carried. It has its own
link to the service, so a long poll never holds up the worker's calls."""

from __future__ import annotations

import threading
from collections.abc import Callable

from collie.schemas import FINISHED, StreamEvent
from labeling_ui.actions import Wake
from labeling_ui.service import AuthRefused, Rejected, ServiceDown, ServiceLink

Wanted = Callable[[StreamEvent], bool]


def run_ended(event: StreamEvent) -> bool:
    """The trainer reported the run over (finished, failed, or stopped by an operator): a label
    on its segments is refused from now on."""
    return event.kind == "status" and event.data.status in FINISHED


class StreamWaiter:
    def __init__(self, name: str, closed: threading.Event, wait_s: float, wake: Callable[[Wake], None]) -> None:
        """`closed` ends the thread; `wait_s` is one long poll; `wake` hands a Wake to the worker."""
        self._closed = closed
        self._wait_s = wait_s
        self._wake = wake
        self._lock = threading.Lock()  # guards the target and the link: the worker sets them, the thread reads
        self._target: tuple[int, int, Wanted | None] | None = None  # (run, after, which wake the worker)
        self._link: ServiceLink | None = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def use(self, link: ServiceLink | None) -> None:
        """The link to poll with (None: signed out; the caller closes the old one)."""
        with self._lock:
            self._link = link

    def follow(self, run_id: int, after: int, wanted: Wanted | None = None) -> None:
        """Wake the worker on `run_id`'s next event after `after` (one that is `wanted`, if given)."""
        with self._lock:
            self._target = (run_id, after, wanted)

    def stop_following(self) -> None:
        with self._lock:
            self._target = None

    def _run(self) -> None:
        while not self._closed.is_set():
            with self._lock:
                target, link = self._target, self._link
            if target is None or link is None:
                self._closed.wait(0.25)
                continue
            try:
                page = link.wait_for_events(target[0], target[1], self._wait_s)
            except (ServiceDown, AuthRefused, Rejected):
                self._closed.wait(1.0)
                continue
            except Exception:  # the link was closed under us (sign-out)
                self._closed.wait(0.25)
                continue
            wanted = target[2]
            with self._lock:
                moved_on = page.last_id > target[1] and self._target == target
                if moved_on:
                    self._target = (target[0], page.last_id, wanted)
            if moved_on and (wanted is None or any(wanted(e) for e in page.events)):
                self._wake(Wake(frozenset(e.kind for e in page.events)))
