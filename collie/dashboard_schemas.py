"""Wire schemas of the operators' dashboard API (/api/dashboard): read-only views the service
computes from what it stores, each bounded in size whatever the run's length."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import ConfigDict, Field

from collie.labels import Label
from collie.schemas import Control, LabelValue, QueryRead, QueueCounts, RolloutsRead, RunRead, RunStatus, Wire

MAX_HISTORY_POINTS = 5000  # the largest metric history one request may ask for
DEFAULT_HISTORY_POINTS = 1000
MAX_LABELLED_SEGMENTS = 400  # newest labelled segments drawn on the map
MAX_LABELLED_POINTS = 4000  # their states, thinned evenly within each segment to fit
LABEL_RATE_WINDOW_S = 300.0  # labels per minute are counted over the last five minutes
MAX_DISAGREEMENTS = 100  # newest queries where labelers or the oracle disagree, listed with their paths


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
    trainer_seen_at: datetime | None = Field(default=None, description="when its own trainer last called")


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
    id: int = Field(description="the labeler's principal id (POST /runs/{id}/labelers/{labeler_id}/discard)")
    name: str
    labels: int = Field(description="queries they hold a label on now (a revision replaces, an undo withdraws)")
    skips: int
    median_s: float | None = Field(description="median seconds per label, of those that reported it")
    agreement: float | None = Field(description="share of their labels the task rule agrees with")
    alpha: float | None = Field(default=None, description="Krippendorff's α of their labels against the others'")
    shared: int = Field(default=0, description="queries they labelled that another labeler labelled too")
    gold_answered: int = Field(default=0, description="gold segments they labelled")
    gold_accuracy: float | None = Field(default=None, description="share of gold segments they labelled right")


class Disagreement(Read):
    """A query whose labelers disagree, or whose label the oracle disagrees with."""

    query_id: str
    session: int
    labels: dict[str, LabelValue] = Field(description="labeler → their current label")
    effective: LabelValue | None = Field(description="null until the run's redundancy is reached")
    oracle: LabelValue | None
    xy: list[list[float]]


class QueryReview(Read):
    """One query for an operator's review in 3D (the dashboard's "replay in 3D", the labeling UI's
    review mode): its segment with the simulator states, each labeler's current label, the label
    it counts as, and the task rule's."""

    query: QueryRead
    labels: dict[str, LabelValue] = Field(description="labeler → their current label")
    effective: LabelValue | None = Field(description="null until the run's redundancy is reached")
    oracle: LabelValue | None = Field(description="the task rule's label; null without a rule or where it cannot judge")
    has_rule: bool = Field(description="the run has a task rule (else only an instruction, or an unreadable rule)")


class LabelingStats(Read):
    queue: QueueCounts
    n_labels: int
    n_total: int | None
    labels_per_min: float = Field(description=f"over the last {LABEL_RATE_WINDOW_S:.0f} s")
    last_label_at: datetime | None
    labelers: list[LabelerStats]
    agreement: float | None = Field(description="effective labels the oracle agrees with (share)")
    judged: int = Field(description="effective labels the oracle could judge")
    redundancy: int = Field(default=1, description="labels from distinct labelers before a query counts")
    gold_rate: float = Field(default=0.0, description="share of each labeler's segments that are gold")
    alpha: float | None = Field(default=None, description="Krippendorff's α (nominal) between labelers")
    alpha_queries: int = Field(default=0, description="queries with two labels or more (α's units)")
    n_disagreements: int = 0
    disagreements: list[Disagreement] = Field(default_factory=list, max_length=MAX_DISAGREEMENTS)
    between_labelers: float | None = Field(
        default=None, description="agreement between labelers (needs no rule): agreeing pairs on shared queries"
    )
    shared_queries: int = Field(default=0, description="queries two or more distinct labelers label now")


class LabelingView(Read):
    labeling: LabelingStats
    labelled: list[LabelledSegment] = Field(max_length=MAX_LABELLED_SEGMENTS)
    n_labelled: int = Field(description="labelled segments in all (the map shows the newest)")


class RunDashboard(LabelingView):
    """Everything the run page draws, read in one transaction; open the run's stream at
    ?after=last_event_id to follow it without a gap."""

    run: RunRead
    task: dict[str, Any] | None = Field(
        description="collie.tasks Task.to_dict() of the run's stored rule, for shading regions; null without a rule"
    )
    task_error: str | None
    rollouts: RolloutsRead | None
    metrics: MetricHistory
    last_event_id: int
    labels: list[LabelName] = Field(
        default_factory=lambda: list(LABEL_NAMES), description="every label, in value order"
    )
