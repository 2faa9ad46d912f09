"""When each run's own trainer process (its requests say X-Collie-Part: trainer) last called the
service (runs.trainer_seen_at): a run whose trainer died stays "waiting for labels" for good, and
the dashboard says so from this.

A live trainer calls at least every few seconds (its event long poll, status and progress), so
the time is written at most every `every_s` per run and caller: one small UPDATE, not one per
request."""

from __future__ import annotations

import threading
import time

from sqlalchemy import update

from backend.db import Database
from backend.models import Run
from backend.services.auth import Caller


class TrainerContact:
    KEPT = 4096  # past this many (run, caller) turns, those already over are forgotten

    def __init__(self, every_s: float = 15.0) -> None:
        self.every_s = every_s
        self._written: dict[tuple[int, int], float] = {}  # (run, caller) → this process's last write
        self._lock = threading.Lock()

    def heard(self, db: Database, run_id: int, caller: Caller) -> None:
        """A trainer process called about `run_id` with `caller`'s token: noted if that is the
        run's own trainer, or an operator (whose token may drive a resumed trainer)."""
        now = time.monotonic()
        with self._lock:
            key = (run_id, caller.id)  # another trainer's call must not spend the run's own turn
            if now - self._written.get(key, -self.every_s) < self.every_s:
                return
            self._written[key] = now
            if len(self._written) > self.KEPT:  # calls about runs that do not exist must not pile up
                self._written = {k: t for k, t in self._written.items() if now - t < self.every_s}
        mine = Run.id == run_id if caller.role == "operator" else (Run.id == run_id) & (Run.created_by == caller.id)
        with db.write() as conn:
            conn.execute(update(Run).where(mine).values(trainer_seen_at=time.time()))
