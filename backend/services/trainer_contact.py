"""When each run's own trainer last called the service (runs.trainer_seen_at): a run whose
trainer died stays "waiting for labels" for good, and the dashboard says so from this.

A live trainer calls at least every few seconds (its event long poll, status and progress), so
the time is written at most every `every_s` per run and caller: one small UPDATE, not one per
request."""

from __future__ import annotations

import threading
import time

from sqlalchemy import update

from backend.db import Database
from backend.models import Run


class TrainerContact:
    def __init__(self, every_s: float = 15.0) -> None:
        self.every_s = every_s
        self._written: dict[tuple[int, int], float] = {}  # (run, caller) → this process's last write
        self._lock = threading.Lock()

    def heard(self, db: Database, run_id: int, principal_id: int) -> None:
        """The trainer `principal_id` called about `run_id`: noted if it created the run."""
        now = time.monotonic()
        with self._lock:
            key = (run_id, principal_id)  # another trainer's call must not spend the run's own turn
            if now - self._written.get(key, -self.every_s) < self.every_s:
                return
            self._written[key] = now
        with db.write() as conn:
            conn.execute(
                update(Run).where(Run.id == run_id, Run.created_by == principal_id).values(trainer_seen_at=time.time())
            )
