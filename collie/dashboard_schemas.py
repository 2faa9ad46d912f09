"""Wire schemas of the operators' dashboard API (/api/dashboard): read-only views the service
computes from what it stores, each bounded in size whatever the run's length."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import ConfigDict, Field

from collie.labels import Label
from collie.schemas import Control, LabelValue, QueueCounts, RolloutsRead, RunRead, RunStatus, Wire

MAX_HISTORY_POINTS = 5000  # the largest metric history one request may ask for
DEFAULT_HISTORY_POINTS = 1000
MAX_LABELLED_SEGMENTS = 400  # newest labelled segments drawn on the map
MAX_LABELLED_POINTS = 4000  # their states, thinned evenly within each segment to fit
LABEL_RATE_WINDOW_S = 300.0  # labels per minute are counted over the last five minutes


class Read(Wire):
    model_config = ConfigDict(strict=False)


class RunSummary(Read):
    """One row of the runs list."""

    id: int
    env: str
    task: str
    method: str
    preset: str | None
    status: RunStatus
    control: Control
    epoch: int
    epochs_total: int | None
    n_labels: int
    n_total: int | None
    queue: QueueCounts
    last_label_at: datetime | None = Field(description="when the latest label (not skip or undo) arrived")
    last_event_id: int
    created_at: datetime
    updated_at: datetime


class RunsPage(Read):
    version: int = Field(description="changes whenever any run's log grows; pass it back as ?after=")
    runs: list[RunSummary]


class MetricHistory(Read):
    """Evaluation metrics over epochs, column-wise, thinned to at most `max_points` rows (every
    `stride`-th row by epoch, and always the newest)."""

    n_stored: int = Field(description="metric rows the run has")
    stride: int
    epochs: list[int]
    created_at: list[float] = Field(description="seconds since the Unix epoch")
    series: dict[str, list[float | None]] = Field(description="name → values; null where a row lacks it")


class LabelName(Read):
    """A label's value and the word the dashboard shows for it (the names live in collie.labels only)."""

    value: LabelValue
    name: str


LABEL_NAMES = [LabelName(value=v, name=v.word) for v in Label]


class LabelledSegment(Read):
    """A labelled segment's states on the x-y map, with the oracle's verdict where the rule judges."""

    query_id: str
    session: int
    label: LabelValue
    oracle: LabelValue | None
    xy: list[list[float]]


class LabelerStats(Read):
    name: str
    labels: int = Field(description="label submissions (revisions included; skips and undos not)")
    skips: int
    median_s: float | None = Field(description="median seconds per label, of those that reported it")
    agreement: float | None = Field(description="share of their labels the task rule agrees with")


class LabelingStats(Read):
    queue: QueueCounts
    n_labels: int
    n_total: int | None
    labels_per_min: float = Field(description=f"over the last {LABEL_RATE_WINDOW_S:.0f} s")
    last_label_at: datetime | None
    labelers: list[LabelerStats]
    agreement: float | None = Field(description="effective labels the oracle agrees with (share)")
    judged: int = Field(description="effective labels the oracle could judge")


class LabelingView(Read):
    labeling: LabelingStats
    labelled: list[LabelledSegment] = Field(max_length=MAX_LABELLED_SEGMENTS)
    n_labelled: int = Field(description="labelled segments in all (the map shows the newest)")


class RunDashboard(LabelingView):
    """Everything the run page draws, read in one transaction; open the run's stream at
    ?after=last_event_id to follow it without a gap."""

    run: RunRead
    task: dict[str, Any] | None = Field(description="collie.tasks Task.to_dict(), for shading regions")
    task_error: str | None
    rollouts: RolloutsRead | None
    metrics: MetricHistory
    last_event_id: int
    labels: list[LabelName] = Field(
        default_factory=lambda: list(LABEL_NAMES), description="every label, in value order"
    )
