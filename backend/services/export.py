"""A run's labels as JSON or CSV: every label event, or the effective label per query."""

from __future__ import annotations

import csv
import io
import json

from sqlalchemy import Connection

from backend.services import labels

EVENT_FIELDS = (
    "id",
    "query_id",
    "session",
    "labeler",
    "kind",
    "value",
    "seconds",
    "client_request_id",
    "revises_event_id",
    "created_at",
)
EFFECTIVE_FIELDS = ("query_id", "session", "label", "event_id", "labeler", "seconds", "labelled_at")


def rows(conn: Connection, run_id: int, effective: bool) -> list[dict[str, object]]:
    if effective:
        return [e.model_dump(mode="json", include=set(EFFECTIVE_FIELDS)) for e in labels.effective_labels(conn, run_id)]
    result: list[dict[str, object]] = []
    after = 0
    while batch := labels.list_events(conn, run_id, after, 10_000):
        result += [e.model_dump(mode="json", include=set(EVENT_FIELDS)) for e in batch]
        after = batch[-1].id
    return result


def render(records: list[dict[str, object]], fmt: str, effective: bool) -> str:
    if fmt == "json":
        return json.dumps(records, indent=1)
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=EFFECTIVE_FIELDS if effective else EVENT_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(records)
    return out.getvalue()
