"""Migration 0006: a database holding sessions from before (some positions posted twice, as the old
resume did) gets one feedback_sessions row per (run, session), and from then on a position is unique."""

from __future__ import annotations

from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import text
from sqlalchemy.exc import IntegrityError

from backend.db import Database
from backend.migrate import alembic_config

from .conftest import DIMS


def test_0006_fills_feedback_sessions_from_the_stored_queries(tmp_path: Path) -> None:
    db = Database(f"sqlite:///{tmp_path / 'old.db'}")
    config = alembic_config(db.url)
    with db.engine.begin() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, "0002")
        conn.execute(
            text(
                "INSERT INTO principals (id, name, role, token_sha256, created_at) VALUES (1, 'tr', 'trainer', 'x', 0)"
            )
        )
        conn.execute(
            text(
                "INSERT INTO runs (id, env, task, method, config, dims, status, control, epoch, n_labels,"
                " last_event_id, created_by, created_at, updated_at) VALUES (1, 'point', 'north', 'collie', '{}',"
                " :dims, 'training', 'run', 3, 0, 0, 1, 0, 0)"
            ),
            {"dims": DIMS.model_dump_json()},
        )
        rows = [("s0-q0", 0, 2, 5.0), ("s0-q1", 0, 2, 6.0), ("s1-q0", 1, 4, 7.0), ("s2-q0", 2, 2, 8.0)]
        for qid, session, epoch, at in rows:
            conn.execute(
                text(
                    "INSERT INTO queries (run_id, query_id, session, epoch, start, score, status, created_at)"
                    " VALUES (1, :qid, :session, :epoch, 0, 0, 'pending', :at)"
                ),
                {"qid": qid, "session": session, "epoch": epoch, "at": at},
            )
    with db.engine.begin() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, "0006")
    with db.engine.begin() as conn:
        got = conn.execute(text("SELECT run_id, session, epoch, created_at FROM feedback_sessions ORDER BY session"))
        assert [tuple(r) for r in got] == [(1, 0, 2, 5.0), (1, 1, 4, 7.0), (1, 2, 2, 8.0)]
    with pytest.raises(IntegrityError), db.engine.begin() as conn:
        conn.execute(text("INSERT INTO feedback_sessions (run_id, session, epoch, created_at) VALUES (1, 1, 9, 0)"))
    db.dispose()
