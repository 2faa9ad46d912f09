"""Wire schemas of the labeling service, written once: the server validates with them and every
client (trainer feedback source, teacher, labeling UI, tests) builds and reads them.

Arrays travel as (nested) lists of finite floats (image observations packed: PackedFrames);
shapes are checked here, and again against the run's env dims on the server. A label is 0 bad,
1 neutral, 2 good; "skip" is a submission that is not a label (it hands the query back to the
pool).
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import zlib
from datetime import datetime
from typing import Annotated, Any, ClassVar, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    FiniteFloat,
    TypeAdapter,
    field_validator,
    model_validator,
)

from collie.env_names import ENV_JOINTS, EnvName
from collie.labels import Label
from collie.task_schemas import MAX_INSTRUCTION, TaskDefinition, Text

_LABELS: dict[int, Label] = {int(v): v for v in Label}  # built once: every label crosses this check


def _exact_label(value: object) -> Label:
    # only the integers 0, 1, 2 (or a Label): no "2", 2.0 or true, which lax enum checks would take
    if isinstance(value, bool) or not isinstance(value, int) or value not in _LABELS:
        raise ValueError(f"a label is the integer {', '.join(str(int(v)) for v in Label)}, got {value!r}")
    return _LABELS[value]


LabelValue = Annotated[Label, BeforeValidator(_exact_label)]  # on the wire the integer: 0 bad, 1 neutral, 2 good
Submission = LabelValue | Literal["skip"]
Role = Literal["operator", "trainer", "labeler"]
RunStatus = Literal["training", "waiting_for_labels", "paused", "finished", "failed"]
Control = Literal["run", "pause", "stop"]
QueryStatus = Literal["pending", "leased", "labelled", "retired"]
EventKind = Literal["label", "skip", "undo"]

FINISHED: frozenset[str] = frozenset({"finished", "failed"})

Name = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:+-]+$")]
QueryId = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:-]+$")]
RequestId = Annotated[str, Field(min_length=1, max_length=128, pattern=r"^[\x21-\x7e]+$")]
# A browser tab's own id (the labeling UI keeps it in the tab's sessionStorage: a reload keeps it,
# another tab has its own). A claim made for a tab is that tab's: only it may label the query.
TabId = Annotated[str, Field(min_length=8, max_length=64, pattern=r"^[A-Za-z0-9_-]+$")]
# Why a label from a tab was refused (409 NotHeld): the tab no longer holds the query because
# another tab of the same labeler holds it, another labeler does, the caller labelled it already
# (in another tab or client), someone else labelled it, the trainer withdrew it, or its claim
# ended (released, or expired and taken back).
NotHeldReason = Literal["other_tab", "other_labeler", "labelled_by_you", "labelled", "retired", "not_claimed"]
OutOfScopeReason = Literal["other_runs", "other_trainer"]  # a token limited to other runs; another trainer's run


# The oracle teacher's own labeler that `collie up --teacher oracle` makes (collie/teacher_principal.py:
# oracle-teacher, -2, …, each limited to its stack's run), and the one `collie serve` installs for
# COLLIE_TEACHER_TOKEN (compose's teacher profile), named apart: it never takes over a stack's
TEACHER_PRINCIPAL = "oracle-teacher"
SERVED_TEACHER_PRINCIPAL = "teacher"
MAX_INT = 2**31 - 1  # fits every database's INTEGER column (PostgreSQL's is 32 bits) and JSON numbers
Count = Annotated[int, Field(ge=0, le=MAX_INT)]
Vector = list[FiniteFloat]
Matrix = list[list[FiniteFloat]]
MAX_FEEDBACK_TIMEOUT_S = 7 * 86_400
MAX_LEASE_S = 3600.0  # the longest claim a labeler may ask for (POST /claim's lease_s)
# how long the trainer waits for a session's labels before it continues with what arrived
FeedbackTimeout = Annotated[float, Field(gt=0, le=MAX_FEEDBACK_TIMEOUT_S, allow_inf_nan=False)]
MAX_REDUNDANCY = 10
# labels from distinct labelers each query needs before it counts (the effective label: docs/service.md)
Redundancy = Annotated[int, Field(ge=1, le=MAX_REDUNDANCY)]
# share of a labeler's segments that are gold (segments whose answer the task rule knows); 0: none
GoldRate = Annotated[float, Field(ge=0, le=0.5, allow_inf_nan=False)]

MAX_CONFIG_BYTES = 64 * 1024
MAX_EXTRA_BYTES = 16 * 1024
MAX_PACKED_CHARS = 16 * 1024 * 1024  # one segment's packed image observations, base64
MAX_UNPACKED_BYTES = 256 * 1024 * 1024  # the same, inflated (n × prod(shape))
MAX_HOLD = 2  # queries one tab may hold at once in a run: the one on screen and the next
MAX_TABS = 4  # a labeler's tabs that hold queries at once in a run (they hold MAX_HOLD each)
MAX_ROLLOUTS = 64
MAX_ROLLOUT_POINTS = 2001
MAX_QPOS_WIDTH = 128  # humanoid's nq is 28
MAX_METRICS = 256
# One segment's bounds (EnvDims allows no more): frames per segment, values per frame, and the
# context path's points (a whole episode's x-y; every claim of the query carries it).
MAX_FRAMES = 10_000
MAX_FRAME_WIDTH = 100_000
MAX_PATH_POINTS = 10_001
MAX_SKILL_DIM = 1_000
MAX_SESSION_QUERIES = 10_000  # the service's own limit (max_queries_per_session) is lower
FrameRows = Annotated[
    list[Annotated[list[FiniteFloat], Field(max_length=MAX_FRAME_WIDTH)]], Field(max_length=MAX_FRAMES)
]


PART_HEADER = "X-Collie-Part"  # which part of collie calls: "trainer" marks a run's trainer as alive


class Wire(BaseModel):
    """Strict: no silent coercion of strings to numbers; unknown fields are an error."""

    model_config = ConfigDict(strict=True, extra="forbid")


def _width(rows: list[list[float]], name: str) -> int:
    """All rows of a matrix have one width; returns it (0 for no rows)."""
    widths = {len(r) for r in rows}
    if len(widths) > 1:
        raise ValueError(f"{name}: rows of unequal length {sorted(widths)}")
    return widths.pop() if widths else 0


def _holds_nul(value: object) -> bool:
    if isinstance(value, str):
        return "\x00" in value
    if isinstance(value, dict):
        return any(_holds_nul(k) or _holds_nul(v) for k, v in value.items())
    return isinstance(value, list) and any(_holds_nul(v) for v in value)


def _bounded_json(value: dict[str, Any], limit: int, name: str) -> dict[str, Any]:
    """Free JSON (a run's config, a segment's extra): finite, valid UTF-8 (no lone surrogate from a
    \\u escape, which would be stored and then break every read of it), no NUL in a key or a
    string (as in free text: no person means it, and PostgreSQL text cannot hold it), at most `limit` bytes."""
    if _holds_nul(value):
        raise ValueError(f"{name}: text must not contain the NUL character (\\u0000)")
    try:
        size = len(json.dumps(value, allow_nan=False, ensure_ascii=False).encode("utf-8"))
    except UnicodeEncodeError:
        raise ValueError(f"{name}: holds a lone UTF-16 surrogate (text must be valid Unicode)") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not plain finite JSON ({exc})") from exc
    if size > limit:
        raise ValueError(f"{name}: {size} bytes, at most {limit}")
    return value


# ---------------------------------------------------------------- runs


class EnvDims(Wire):
    """Shapes the server checks every posted segment against."""

    obs_dim: int = Field(ge=1, le=100_000)
    nq: int = Field(ge=1, le=10_000)
    nv: int = Field(ge=0, le=10_000)
    horizon: int = Field(ge=1, le=10_000, description="H, states per segment")
    skill_dim: int = Field(ge=1, le=1_000)


class RunCreate(Wire):
    env: EnvName
    task: Name
    method: Name
    config: dict[str, Any] = Field(default_factory=dict)
    dims: EnvDims
    n_total: int | None = Field(
        default=None,
        ge=0,
        le=MAX_INT,
        description="the most queries the run may ask (its label budget; sessions past it are refused)",
    )
    epochs_total: int | None = Field(default=None, ge=0, le=MAX_INT)
    feedback_timeout_s: FeedbackTimeout | None = Field(
        default=None, description="seconds the trainer waits for a session's labels; null: every label"
    )
    redundancy: Redundancy = Field(default=1, description="labels from distinct labelers per query")
    gold_rate: GoldRate = Field(default=0.0, description="share of each labeler's segments that are gold")
    task_definition: TaskDefinition | None = Field(default=None, description="the run's rule, judged by every client")
    instruction: Text | None = Field(
        default=None, min_length=1, max_length=MAX_INSTRUCTION, description="intent in words, for a run without a rule"
    )
    client_request_id: RequestId | None = Field(
        default=None,
        description="your id for this creation: a repeat of it by the same trainer answers the run the first made "
        "(200), so a client that lost the answer may send it again; null: every post makes a run",
    )

    @model_validator(mode="after")
    def _rule_or_instruction(self) -> RunCreate:
        if self.task_definition is not None and self.instruction is not None:
            raise ValueError("a run has a task_definition (a rule) or an instruction (no rule), not both")
        joints = ENV_JOINTS[self.env]
        if (self.dims.nq, self.dims.nv) != joints:  # the labeling UI could replay none of its segments
            raise ValueError(
                f"dims nq {self.dims.nq}, nv {self.dims.nv} are not {self.env}'s (nq {joints[0]}, nv {joints[1]})"
            )
        if self.task_definition is not None and self.task_definition.name != self.task:
            # the run would read as one task and be judged by another's rule
            raise ValueError(
                f"task {self.task!r} and its task_definition (named {self.task_definition.name!r}) must name one task"
            )
        return self

    @field_validator("config")
    @classmethod
    def _config_small(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _bounded_json(v, MAX_CONFIG_BYTES, "config")


class QueueCounts(Wire):
    pending: int = 0
    leased: int = 0
    labelled: int = 0
    retired: int = 0


class RunRead(Wire):
    model_config = ConfigDict(strict=False)
    id: int
    env: str
    task: str
    method: str
    config: dict[str, Any]
    dims: EnvDims
    status: RunStatus
    control: Control
    epoch: int
    n_labels: int = Field(description="queries with an effective label")
    n_total: int | None
    epochs_total: int | None
    last_event_id: int
    queue: QueueCounts
    created_at: datetime
    updated_at: datetime
    feedback_timeout_s: float | None = Field(default=None, description="null: the trainer waits for every label")
    redundancy: int = Field(default=1, description="labels from distinct labelers before a query counts")
    gold_rate: float = Field(default=0.0, description="share of each labeler's segments that are gold")
    task_definition: TaskDefinition | None = Field(default=None, description="the run's rule as stored")
    instruction: str | None = Field(default=None, description="a run without a rule: the labelers' instruction")
    instructions: str = Field(default="", description="an operator's instructions for the run's labelers")
    trainer_seen_at: datetime | None = Field(
        default=None, description="when the run's own trainer last called the service (written every 15 s at most)"
    )


class QualitySettings(Wire):
    """An operator's labeler quality control for a run. Redundancy applies to labels submitted from
    then on (a query already counted stays counted); gold_rate to the segments served from then on.
    A field left out (or null) keeps the run's value; a new run has r = 1 and no gold."""

    redundancy: Redundancy | None = None
    gold_rate: GoldRate | None = None


MAX_INSTRUCTIONS = 4000  # characters of an operator's free-text instructions for a run's labelers


class RunInstructions(Wire):
    """An operator's free-text instructions for a run's labelers, shown with the task (empty: none)."""

    text: Text = Field(max_length=MAX_INSTRUCTIONS)


class FeedbackPolicy(Wire):
    """An operator's feedback timeout policy: the trainer continues after `timeout_s` seconds of a
    session with the labels that arrived (later ones come as revisions); null waits for every label."""

    timeout_s: FeedbackTimeout | None


class StatusUpdate(Wire):
    status: RunStatus
    epoch: int | None = Field(default=None, ge=0, le=MAX_INT)
    message: Text | None = Field(default=None, max_length=1000)


class RunExtend(Wire):
    """More epochs for a run (its trainer resumed with a larger --epochs): a finished run reopens."""

    epochs_total: int = Field(ge=1, le=MAX_INT)


# ---------------------------------------------------------------- queries


class PackedFrames(Wire):
    """H image observations as raw uint8 bytes, zlib-compressed, base64 (collie/frames.py packs
    and unpacks). The decompressed size must be n × prod(shape); checked without inflating more."""

    dtype: Literal["uint8"]
    n: Count
    shape: list[Annotated[int, Field(ge=1, le=4096)]] = Field(min_length=1, max_length=4, description="one frame")
    zlib_b64: str = Field(max_length=MAX_PACKED_CHARS)

    @model_validator(mode="after")
    def _size(self) -> PackedFrames:
        want = self.n * math.prod(self.shape)
        if want > MAX_UNPACKED_BYTES:
            raise ValueError(f"{self.n} frames of {self.shape} are {want} bytes, more than {MAX_UNPACKED_BYTES}")
        try:
            inflate = zlib.decompressobj()
            got = len(inflate.decompress(base64.b64decode(self.zlib_b64, validate=True), want + 1))
        except (binascii.Error, zlib.error) as exc:
            raise ValueError(f"zlib_b64 is not base64 of zlib data: {exc}") from None
        if got != want or not inflate.eof:
            raise ValueError(
                f"packed frames hold {'more than ' if got > want else ''}{got} bytes, "
                f"{self.n} × {self.shape} needs {want}"
            )
        return self


class QueryFrames(Wire):
    """What a labeler replays and what the trainer rebuilds its labelled sets from (H frames).
    Image observations travel packed in obs_packed (obs is then empty)."""

    skill: Vector = Field(max_length=MAX_SKILL_DIM)
    obs: FrameRows = Field(default_factory=list)
    obs_packed: PackedFrames | None = Field(default=None, description="image observations (obs empty)")
    xy: FrameRows
    pitch: list[FiniteFloat | None] | None = Field(
        default=None, max_length=MAX_FRAMES, description="null where undefined"
    )
    qpos: FrameRows
    qvel: FrameRows
    path_xy: list[Annotated[list[FiniteFloat], Field(max_length=2)]] | None = Field(
        default=None, max_length=MAX_PATH_POINTS, description="the whole trajectory's x-y, for context"
    )

    @model_validator(mode="after")
    def _shapes(self) -> QueryFrames:
        h = len(self.xy)
        if self.obs_packed is not None and (self.obs or self.obs_packed.n != h):
            raise ValueError(f"obs_packed needs an empty obs and {h} frames, has {self.obs_packed.n}")
        for name in ("obs", "qpos", "qvel") + (("pitch",) if self.pitch is not None else ()):
            if name == "obs" and self.obs_packed is not None:
                continue
            if len(getattr(self, name)) != h:
                raise ValueError(f"{name} has {len(getattr(self, name))} frames, xy has {h}")
        for name in ("obs", "qpos", "qvel"):
            _width(getattr(self, name), name)
        if h and _width(self.xy, "xy") != 2:
            raise ValueError("xy rows must have 2 columns")
        if self.path_xy and _width(self.path_xy, "path_xy") != 2:
            raise ValueError("path_xy rows must have 2 columns")
        return self

    def shape_errors(self, dims: EnvDims) -> list[str]:
        """Mismatches against the run's env dims (empty when the segment fits)."""
        want = {"obs": dims.obs_dim, "qpos": dims.nq, "qvel": dims.nv}
        errors = [f"{len(self.xy)} frames, run expects H={dims.horizon}"] if len(self.xy) != dims.horizon else []
        if self.obs_packed is not None and math.prod(self.obs_packed.shape) != dims.obs_dim:
            errors.append(f"packed obs of {self.obs_packed.shape}, run expects {dims.obs_dim} values per frame")
        errors += [
            f"{name} width {len(getattr(self, name)[0])}, run expects {w}"
            for name, w in want.items()
            if getattr(self, name) and len(getattr(self, name)[0]) != w
        ]
        if len(self.skill) != dims.skill_dim:
            errors.append(f"skill has {len(self.skill)} dims, run expects {dims.skill_dim}")
        return errors


class QueryIn(QueryFrames):
    query_id: QueryId
    start: Count
    score: FiniteFloat = 0.0
    extra: dict[str, Any] = Field(default_factory=dict)

    @field_validator("extra")
    @classmethod
    def _extra_small(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _bounded_json(v, MAX_EXTRA_BYTES, "extra")


class SessionPost(Wire):
    """One feedback session's M segments, posted in one call. `session` is the session's position in
    the run's feedback schedule (0, 1, …): a position is posted once; posting it again stores nothing
    and answers with the session stored for it (SessionPosted.reused)."""

    session: Count
    epoch: Count
    queries: list[QueryIn] = Field(min_length=1, max_length=MAX_SESSION_QUERIES)

    @model_validator(mode="after")
    def _unique_ids(self) -> SessionPost:
        ids = [q.query_id for q in self.queries]
        if len(set(ids)) != len(ids):
            raise ValueError("query_id values repeat within the session")
        return self


class SessionPosted(Wire):
    session: int
    epoch: int = Field(description="the epoch the session was first posted at")
    created: list[str]
    existing: list[str] = Field(description="ids already stored; kept as they were (the service is the truth)")
    reused: bool = Field(
        default=False, description="this position was posted before: nothing was stored; query_ids are its queries"
    )
    query_ids: list[str] = Field(default_factory=list, description="the session's queries, as stored, in order")


class RetireRequest(Wire):
    """Unlabelled queries the trainer will never use (left over from before a restart)."""

    query_ids: list[QueryId] = Field(min_length=1, max_length=10_000)


class Retired(Wire):
    retired: list[str]
    not_retired: list[str] = Field(description="labelled (or unknown) ids, left as they were")


class QuerySummary(Wire):
    model_config = ConfigDict(strict=False)
    run_id: int
    query_id: str
    session: int
    epoch: int
    start: int
    score: float
    status: QueryStatus
    label: LabelValue | None
    lease_owner: str | None
    lease_expires_at: datetime | None
    created_at: datetime


class QueryRead(QuerySummary):
    skill: list[float]
    obs: list[list[float]]
    obs_packed: PackedFrames | None = None
    xy: list[list[float]]
    pitch: list[float | None] | None
    qpos: list[list[float]]
    qvel: list[list[float]]
    path_xy: list[list[float]] | None
    extra: dict[str, Any]


class ClaimRead(Wire):
    model_config = ConfigDict(strict=False)
    query: QueryRead
    lease_expires_at: datetime
    held: list[QueryId] = Field(default_factory=list, description="every query the caller holds in the run now")


class Released(Wire):
    query_id: QueryId
    status: QueryStatus = Field(
        description="the query's status after the call (pending once released; retired for a gold copy)"
    )


# ---------------------------------------------------------------- labels


class LabelSubmit(Wire):
    query_id: QueryId
    value: Submission
    seconds: FiniteFloat | None = Field(default=None, ge=0, le=86_400, description="time spent")
    client_request_id: RequestId
    tab: TabId | None = Field(
        default=None,
        description="the tab that claimed the query: then only a tab holding its lease may label it (409 NotHeld "
        "otherwise), never as a revision; null: any claim of the caller's, or a revision of their own label",
    )

    @field_validator("value", mode="before")
    @classmethod
    def _label_or_skip(cls, v: object) -> object:
        # one error for any other value (the union's two would name pydantic's internals), and no
        # true or 1.0, which Literal[1] would take (they equal 1 in Python)
        if v == "skip":
            return v
        try:
            return _exact_label(v)
        except ValueError:
            raise ValueError(f"a label is the integer 0, 1 or 2, or the string 'skip'; got {v!r}") from None


class UndoRequest(Wire):
    query_id: QueryId
    client_request_id: RequestId
    tab: TabId | None = Field(default=None, description="the tab the query comes back to, under a fresh lease")


class LabelEventRead(Wire):
    model_config = ConfigDict(strict=False)
    id: int
    run_id: int
    query_id: str
    session: int
    labeler: str
    kind: EventKind
    value: LabelValue | None
    seconds: float | None
    client_request_id: str
    revises_event_id: int | None
    created_at: datetime


class LabelAck(Wire):
    model_config = ConfigDict(strict=False)
    event: LabelEventRead
    label: LabelValue | None = Field(description="the query's effective label after this event")
    query_status: QueryStatus
    duplicate: bool = Field(description="true when this client_request_id was seen before")
    next: ClaimRead | None = Field(default=None, description="with ?next=true: the labeler's next query, if any")


class VotesDiscarded(Wire):
    """POST /runs/{id}/labelers/{labeler_id}/discard (operator): one labeler's votes in a run withdrawn."""

    run_id: int
    labeler: str
    queries: list[QueryId] = Field(description="the queries whose vote of this labeler was withdrawn")
    withdrawn: list[QueryId] = Field(description="those whose effective label went with it (the trainer is told)")


class MyLabel(Wire):
    """One query the caller labelled in a run (GET /runs/{id}/labels/mine): their latest label of it."""

    model_config = ConfigDict(strict=False)

    run_id: int
    query_id: str
    session: int
    label: LabelValue = Field(description="the caller's latest label of the query")
    event_id: int
    labelled_at: datetime
    revisions: int = Field(description="the caller's label events on the query beyond the first")
    in_effect: bool = Field(description="your label stands as your vote: false once undone (by you or an operator)")
    xy: list[list[float]] = Field(description="the segment's x-y, for a small inset")


class EffectiveLabel(Wire):
    model_config = ConfigDict(strict=False)
    query_id: str
    session: int
    label: LabelValue
    event_id: int
    labeler: str
    seconds: float | None
    labelled_at: datetime


class LabelledQuery(Wire):
    """A query with its effective label and frames: what a restarted trainer rebuilds D0/D1/D2 from."""

    model_config = ConfigDict(strict=False)
    query: QueryRead
    label: LabelValue
    event_id: int


class LabelledPage(Wire):
    items: list[LabelledQuery]
    next_cursor: int | None


# ---------------------------------------------------------------- stream


# What each kind of event says (its `data`); the service builds them, every client reads them.


class EventData(Wire):
    model_config = ConfigDict(strict=False)
    kind: ClassVar[str]  # the event kind this data travels under


class QueriesPosted(EventData):
    kind = "queries"
    session: int
    epoch: int
    query_ids: list[str]


class QueriesRetired(EventData):
    kind = "retired"
    query_ids: list[str]


class LabelChanged(EventData):
    """A query's effective label is now `label` (kind "label"), or it has none (kind "withdrawn")."""

    kind = "label"
    query_id: str
    session: int
    event_id: int = Field(description="the label event that made the change")
    labeler: str
    label: LabelValue | None


class LabelWithdrawn(LabelChanged):
    kind = "withdrawn"


class StatusChanged(EventData):
    kind = "status"
    status: RunStatus
    epoch: int
    message: str | None = None


class ControlChanged(EventData):
    kind = "control"
    control: Control


class PolicyChanged(EventData):
    kind = "policy"
    timeout_s: float | None


class MetricsPosted(EventData):
    kind = "metrics"
    id: int
    epoch: int
    values: dict[str, float]


class RolloutsPosted(EventData):
    kind = "rollouts"
    id: int
    epoch: int
    n: int


class _Event(Wire):
    model_config = ConfigDict(strict=False)
    id: int = Field(description="per-run, strictly increasing; resume with ?after=id")
    run_id: int
    created_at: datetime


class QueriesEvent(_Event):
    kind: Literal["queries"]
    data: QueriesPosted


class RetiredEvent(_Event):
    kind: Literal["retired"]
    data: QueriesRetired


class LabelChangedEvent(_Event):
    kind: Literal["label"]
    data: LabelChanged


class WithdrawnEvent(_Event):
    kind: Literal["withdrawn"]
    data: LabelWithdrawn


class StatusEvent(_Event):
    kind: Literal["status"]
    data: StatusChanged


class ControlEvent(_Event):
    kind: Literal["control"]
    data: ControlChanged


class PolicyEvent(_Event):
    kind: Literal["policy"]
    data: PolicyChanged


class MetricsEvent(_Event):
    kind: Literal["metrics"]
    data: MetricsPosted


class RolloutsEvent(_Event):
    kind: Literal["rollouts"]
    data: RolloutsPosted


# On the wire: {"id", "run_id", "kind", "data", "created_at"}, `data` shaped by `kind`.
StreamEvent = Annotated[
    QueriesEvent
    | RetiredEvent
    | LabelChangedEvent
    | WithdrawnEvent
    | StatusEvent
    | ControlEvent
    | PolicyEvent
    | MetricsEvent
    | RolloutsEvent,
    Field(discriminator="kind"),
]
STREAM_EVENT: TypeAdapter[StreamEvent] = TypeAdapter(StreamEvent)


class EventPage(Wire):
    model_config = ConfigDict(strict=False)
    events: list[StreamEvent]
    last_id: int = Field(description="id to pass as ?after= next time")


# ---------------------------------------------------------------- rollouts and metrics


class MetricsIn(Wire):
    epoch: Count
    values: dict[Annotated[Text, Field(min_length=1, max_length=64)], FiniteFloat] = Field(max_length=MAX_METRICS)


class MetricsRead(MetricsIn):
    model_config = ConfigDict(strict=False)
    id: int
    run_id: int
    created_at: datetime


class Rollout(Wire):
    skill: Vector = Field(max_length=MAX_SKILL_DIM)
    xy: Matrix = Field(max_length=MAX_ROLLOUT_POINTS)
    pitch: list[FiniteFloat | None] | None = Field(default=None, max_length=MAX_ROLLOUT_POINTS)
    qpos: Matrix | None = Field(
        default=None, max_length=MAX_ROLLOUT_POINTS, description="simulator state at the xy points (3D replay)"
    )
    stride: int = Field(default=1, ge=1, le=100_000, description="environment steps between two consecutive points")
    extra: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _shape(self) -> Rollout:
        if self.xy and _width(self.xy, "xy") != 2:
            raise ValueError("xy rows must have 2 columns")
        if self.pitch is not None and len(self.pitch) != len(self.xy):
            raise ValueError(f"pitch has {len(self.pitch)} values, xy {len(self.xy)} points: one per point")
        if self.qpos is not None:
            if len(self.qpos) != len(self.xy):
                raise ValueError(f"qpos has {len(self.qpos)} rows, xy {len(self.xy)}: one state per point")
            if self.qpos and _width(self.qpos, "qpos") > MAX_QPOS_WIDTH:
                raise ValueError(f"qpos rows may have at most {MAX_QPOS_WIDTH} values")
        _bounded_json(self.extra, MAX_EXTRA_BYTES, "extra")
        return self


class RolloutsIn(Wire):
    epoch: Count
    rollouts: list[Rollout] = Field(max_length=MAX_ROLLOUTS)


class RolloutsRead(RolloutsIn):
    model_config = ConfigDict(strict=False)
    id: int
    run_id: int
    created_at: datetime


# ---------------------------------------------------------------- people and health


MAX_SCOPED_RUNS = 1000


def _some_runs(runs: list[int] | None) -> list[int] | None:
    if runs == []:
        raise ValueError("[] would make the token valid for no run: name at least one run, or null for every run")
    return runs


ScopedRuns = Annotated[
    list[Annotated[int, Field(ge=1, le=MAX_INT)]] | None,
    Field(max_length=MAX_SCOPED_RUNS, description="a labeler limited to these runs; null: every run"),
    AfterValidator(_some_runs),
]


class LabelerCreate(Wire):
    name: Name
    role: Role = "labeler"
    runs: ScopedRuns = None

    @model_validator(mode="after")
    def _runs_for_labelers(self) -> LabelerCreate:
        if self.runs is not None and self.role != "labeler":
            raise ValueError(f"only a labeler token can be limited to runs, not a {self.role} token")
        return self


class LabelerScope(Wire):
    """PUT /labelers/{id}/runs: the runs a labeler may work on from now on (null: every run)."""

    runs: ScopedRuns


class LabelerRead(Wire):
    model_config = ConfigDict(strict=False)
    id: int
    name: str
    role: Role
    created_at: datetime
    revoked: bool
    runs: list[int] | None = Field(default=None, description="the runs a labeler is limited to; null: every run")


class Me(Wire):
    id: int
    name: str
    role: Role


class LabelerCreated(LabelerRead):
    token: str = Field(description="shown once; the service keeps only its sha256")


class Health(Wire):
    status: Literal["ok"]
    version: str
    database: str


class ErrorBody(Wire):
    detail: Any


class StartupMark(Wire):
    """One line of a stack's OUT/logs/startup.jsonl (collie/startup.py): `what` ended at wall time
    `t` (seconds since the epoch) in `part`, when the process had used `cpu` seconds of CPU (all its
    threads; on a busy machine the CPU split stays close to a quiet one's, the wall split stretches)."""

    t: float
    cpu: float
    part: str
    pid: int
    what: str
    epoch: int | None = None


class OutOfScope(Wire):
    """403 for a run outside a valid token's scope (a labeler limited to other runs, a trainer on
    another trainer's run): unlike a wrong or revoked token, the caller may go on with other runs."""

    detail: str
    reason: OutOfScopeReason
    run_id: int


class NotHeld(Wire):
    """409 on a label from a tab that does not hold the query's lease: why, as a value a UI can word."""

    detail: str
    reason: NotHeldReason
    query_id: QueryId
