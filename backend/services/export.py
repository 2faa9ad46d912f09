"""A run's labels as JSON or CSV: every label event, or the effective label per query, each value
with its name beside it (stored 0 bad, 1 neutral, 2 good; the labeling keys are 1, 2, 3)."""

from __future__ import annotations

import csv
import io
import json

from sqlalchemy import Connection

from backend.services import labels
from collie.labels import Label

EVENT_FIELDS = (
    "id",
    "query_id",
    "session",
    "labeler",
    "kind",
    "value",
    "value_name",
    "seconds",
    "client_request_id",
    "revises_event_id",
    "created_at",
)
# A text cell that starts with one of these is run as a formula by spreadsheets (CSV injection): a
# labeler's client_request_id may start with any of them.
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
EFFECTIVE_FIELDS = ("query_id", "session", "label", "label_name", "event_id", "labeler", "seconds", "labelled_at")


def name_of(value: int | None) -> str | None:
    return None if value is None else Label(value).word


def rows(conn: Connection, run_id: int, effective: bool) -> list[dict[str, object]]:
    """Records in the field order of EFFECTIVE_FIELDS / EVENT_FIELDS."""
    if effective:
        found = [e.model_dump(mode="json") for e in labels.effective_labels(conn, run_id)]
        return [{k: name_of(e["label"]) if k == "label_name" else e[k] for k in EFFECTIVE_FIELDS} for e in found]
    result: list[dict[str, object]] = []
    after = 0
    while batch := labels.list_events(conn, run_id, after, 10_000):
        dumped = [e.model_dump(mode="json") for e in batch]
        result += [{k: name_of(e["value"]) if k == "value_name" else e[k] for k in EVENT_FIELDS} for e in dumped]
        after = batch[-1].id
    return result


def render(records: list[dict[str, object]], fmt: str, effective: bool) -> str:
    if fmt == "json":
        return json.dumps(records, indent=1)
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=EFFECTIVE_FIELDS if effective else EVENT_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: spreadsheet_safe(v) for k, v in r.items()} for r in records)
    return out.getvalue()


def spreadsheet_safe(value: object) -> object:
    """A text cell a spreadsheet would run as a formula gets a leading apostrophe (OWASP's advice for
    CSV files), which spreadsheets show as text; numbers and the JSON export are left as they are."""
    return "'" + value if isinstance(value, str) and value.startswith(FORMULA_STARTS) else value
