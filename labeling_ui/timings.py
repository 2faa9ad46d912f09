"""Key → next first frame, one row per label that showed the next segment: appended by the tab's
worker, read by the labeling benchmark from its own thread (hence the lock)."""

from __future__ import annotations

import threading


class KeyTimings:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._rows: list[dict[str, float | str]] = []

    def append(self, row: dict[str, float | str]) -> None:
        with self._lock:
            self._rows.append(row)

    def snapshot(self) -> list[dict[str, float | str]]:
        with self._lock:
            return list(self._rows)
