"""Labels from the labeling service, over HTTP (Algorithm 1, lines 5–7, with people in the loop).

The trainer's side of the contract (docs/service.md):
- `collect` posts the session's segments in one call, marks the run waiting_for_labels and reads
  the run's event log (long poll, resumable by event id) until every segment of the session has an
  effective label — or, with `timeout_s`, until that many seconds passed (then it goes on with what
  arrived; later labels come through `revisions`). An operator may change `timeout_s` at any time
  (a "policy" event): the session being waited on is then re-timed from its start, so a shorter
  timeout that has already passed releases it at once, and None waits for every label again.
  A stop raises StopRequested; while paused it keeps waiting and does not return.
- Every label the trainer is given is remembered with its value, so a label reaches the trainer
  once, and a change of it (undo, relabel, a late label) once more as a revision.
- `history` returns the labelled segments of the run for a restarted trainer, which replays from
  its checkpoint. A session is identified by its schedule position (`session`): re-posting one
  already posted (the replay reaches it again) stores nothing; `collect` then replaces the given
  segments, in place in the list, by the stored session's and waits only for the labels it still
  lacks. Unlabelled leftovers of sessions before the first one posted are retired on the service,
  so a label the trainer cannot use is never taken.
- A segment id the service already holds in a new session keeps the stored segment: `collect`
  copies the stored arrays into the given segment in place.
- The service going away (restart, network) is waited out with backoff; `report` and `control`
  never block training for long and never raise.
numpy only: no torch here, and no database — only HTTP.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from typing import Any, Literal, TypeVar

import numpy as np

from collie.client import ApiError, CollieClient, Unreachable
from collie.frames import pack_frames, unpack_frames
from collie.schemas import (
    MAX_METRICS,
    MAX_QPOS_WIDTH,
    MAX_ROLLOUT_POINTS,
    MAX_ROLLOUTS,
    EventPage,
    MetricsIn,
    QueryIn,
    QueryRead,
    Rollout,
    RolloutsIn,
    RunCreate,
    RunStatus,
    SessionPost,
)
from trainer.feedback.base import FeedbackSource, LabelEvent, Segment, StopRequested

log = logging.getLogger(__name__)
events_page_size = 1000  # the service's largest page
T = TypeVar("T")
Label = Literal[0, 1, 2]


class HttpFeedback(FeedbackSource):
    """A FeedbackSource backed by the labeling service at `api` for run `run_id` (trainer token)."""

    def __init__(
        self,
        api: str,
        token: str,
        run_id: int,
        *,
        timeout_s: float | None = None,
        wait_chunk_s: float = 10.0,
        max_backoff_s: float = 5.0,
        report_timeout_s: float = 5.0,
    ) -> None:
        self.run_id = run_id
        self.timeout_s = timeout_s
        self.wait_chunk_s = wait_chunk_s
        self.max_backoff_s = max_backoff_s
        self.client = CollieClient(api, token)
        self._reporter = CollieClient(api, token, timeout_s=report_timeout_s)
        self._report_quiet_until = 0.0
        self._after = 0  # last event id applied from the run's log
        self._labels: dict[str, Label | None] = {}  # effective labels, as the log says
        self._given: dict[str, Label | None] = {}  # what the trainer was handed, per known query
        self._changed: set[str] = set()  # queries whose label moved since the last revisions()
        self._control: Literal["run", "pause", "stop"] = "run"
        self._shown_status: RunStatus | None = None
        self._swept = False  # leftovers of sessions before the first collect retired?

    @classmethod
    def create(cls, api: str, token: str, spec: RunCreate, **kwargs: Any) -> HttpFeedback:
        """Create the run on the service and return a source for it (timeout_s defaults to the
        spec's feedback_timeout_s)."""
        kwargs.setdefault("timeout_s", spec.feedback_timeout_s)
        with CollieClient(api, token) as client:
            run = client.create_run(spec)
        return cls(api, token, run.id, **kwargs)

    # ---------------------------------------------------------------- the interface

    def collect(self, session: int, epoch: int, segments: list[Segment]) -> list[LabelEvent]:
        if not self._swept:
            self._retire_leftovers(before_session=session)
            self._swept = True
        body = SessionPost(session=session, epoch=epoch, queries=[to_wire(s) for s in segments])
        posted = self._retry(lambda: self.client.post_session(self.run_id, body))
        if posted.reused:  # this position was posted before (a resumed trainer): its queries, not new ones
            stored = [self._retry(lambda q=q: self.client.query(self.run_id, q)) for q in posted.query_ids]
            given = {s.query_id: s for s in segments}
            for q in stored:  # a segment under a stored id is overwritten in place (callers may hold its arrays)
                if q.query_id in given:
                    adopt(given[q.query_id], q)
            segments[:] = [given.get(q.query_id) or from_wire(q) for q in stored]
            ids = [q.query_id for q in stored if q.status != "retired"]  # closed ones will get no label
        else:
            by_id = {s.query_id: s for s in segments}
            for query_id in posted.existing:
                adopt(by_id[query_id], self._retry(lambda q=query_id: self.client.query(self.run_id, q)))
            ids = [s.query_id for s in segments]
        for s in segments:
            self._given.setdefault(s.query_id, None)
        started = time.monotonic()  # the deadline is started + self.timeout_s, as the policy says now
        self._show("waiting_for_labels", epoch)
        wait = 0.0  # first look without waiting: the labels may all be in already (a re-posted session)
        while True:
            self._pump(wait)
            if self._control == "stop":
                raise StopRequested(f"run {self.run_id} was stopped by an operator")
            if self._control == "pause":
                self._show("paused", epoch)
                wait = self.wait_chunk_s  # labels keep arriving while paused; we return after a resume
                continue
            self._show("waiting_for_labels", epoch)
            left = math.inf if self.timeout_s is None else started + self.timeout_s - time.monotonic()
            if not self._missing(ids) or left <= 0:
                break
            wait = min(self.wait_chunk_s, left)
        self._show("training", epoch)
        return self._hand_over(ids)

    def revisions(self) -> list[LabelEvent]:
        try:
            self._pump(0.0, patient=False)
        except (Unreachable, ApiError) as exc:
            log.warning("labeling service unreachable, revisions wait: %s", exc)
            return []
        return self._hand_over([q for q in self._changed if q in self._given])

    def control(self) -> Literal["run", "pause", "stop"]:
        try:
            self._pump(0.0, patient=False)
        except (Unreachable, ApiError) as exc:
            log.warning("labeling service unreachable, keeping control=%s: %s", self._control, exc)
        if self._control == "pause":
            self._show("paused", None)
        elif self._shown_status == "paused":
            self._show("training", None)
        return self._control

    def report(self, kind: Literal["status", "metrics", "rollouts"], payload: dict) -> None:
        if (kind != "status" or payload.get("progress")) and time.monotonic() < self._report_quiet_until:
            return  # the service failed recently: skip the bulky reports, do not slow training down
        try:
            if kind == "status":
                status, message = _run_status(str(payload.get("status", "")), payload.get("error"))
                self._reporter.set_status(self.run_id, status, _epoch(payload), message)
                self._shown_status = status
            elif kind == "metrics":
                self._reporter.post_metrics(
                    self.run_id, MetricsIn(epoch=_epoch(payload) or 0, values=flat_numbers(payload))
                )
            elif kind == "rollouts":
                self._reporter.post_rollouts(self.run_id, rollouts_of(payload))
        except Exception as exc:  # best effort by contract: a dashboard never stops training
            log.warning("report %s not delivered: %s", kind, exc)
            self._report_quiet_until = time.monotonic() + 10.0  # status changes (rare) are still tried

    def history(self) -> list[tuple[Segment, int]]:
        """Every labelled segment of the run, once each (the trainer rebuilds D0/D1/D2 from it)."""
        self._pump(0.0)
        items = self._retry(lambda: list(self.client.labelled(self.run_id)))
        result = []
        for item in items:
            self._given[item.query.query_id] = item.label
            self._changed.discard(item.query.query_id)
            result.append((from_wire(item.query), int(item.label)))
        return result  # leftovers stay open: the resumed loop replays their sessions and waits for them

    def close(self) -> None:
        self.client.close()
        self._reporter.close()

    # ---------------------------------------------------------------- the log

    def _pump(self, wait_s: float, patient: bool = True) -> None:
        """Apply the run's new events, waiting up to wait_s for the first. Patient: wait out an
        unreachable service (collect, history); else raise Unreachable at once (polls between epochs)."""
        page = self._next_page(wait_s, patient)
        while len(page.events) == events_page_size:  # catch up on a long backlog at once
            page = self._next_page(0.0, patient)

    def _next_page(self, wait_s: float, patient: bool) -> EventPage:
        def call() -> EventPage:
            return self.client.events(self.run_id, after=self._after, wait_s=wait_s)

        page = self._retry(call) if patient else call()
        self._apply(page.events)
        return page

    def _apply(self, events: list[Any]) -> None:
        for event in events:
            if event.kind in ("label", "withdrawn"):
                query_id = event.data["query_id"]
                self._labels[query_id] = event.data["label"]
                self._changed.add(query_id)
            elif event.kind == "control":
                self._control = event.data["control"]
            elif event.kind == "policy":
                self.timeout_s = event.data["timeout_s"]
            self._after = event.id

    def _missing(self, ids: list[str]) -> bool:
        return any(self._labels.get(q) is None for q in ids)

    def _hand_over(self, ids: list[str]) -> list[LabelEvent]:
        """Label events for queries whose effective label differs from what the trainer holds."""
        handed = []
        for query_id in ids:
            label = self._labels.get(query_id)
            self._changed.discard(query_id)
            if label != self._given.get(query_id):
                self._given[query_id] = label
                handed.append(LabelEvent(query_id, label))
        return handed

    # ---------------------------------------------------------------- plumbing

    def _retire_leftovers(self, before_session: int) -> None:
        """Unlabelled queries of earlier sessions this trainer does not hold will never be used:
        close them, so nobody labels what the trainer cannot apply."""
        summaries = self._retry(lambda: self.client.queries(self.run_id, limit=5000))
        leftovers = [
            q.query_id
            for q in summaries
            if q.session < before_session and q.status in ("pending", "leased") and q.query_id not in self._given
        ]
        if leftovers:
            retired = self._retry(lambda: self.client.retire(self.run_id, leftovers))
            log.info("retired %d unlabelled leftover queries", len(retired.retired))

    def _show(self, status: RunStatus, epoch: int | None) -> None:
        if status != self._shown_status:
            self.report("status", {"status": status, "epoch": epoch})

    def _retry(self, call: Callable[[], T]) -> T:
        """Call until the service answers: waits out restarts with backoff; 4xx errors raise."""
        delay = 0.1
        while True:
            try:
                return call()
            except Unreachable as exc:
                problem: Exception = exc
            except ApiError as exc:
                if exc.status < 500 and exc.status != 429:
                    raise
                problem = exc
            log.warning("labeling service unavailable (%s); retrying in %.1f s", problem, delay)
            time.sleep(delay)
            delay = min(delay * 2, self.max_backoff_s)


# ---------------------------------------------------------------- conversions


def to_wire(s: Segment) -> QueryIn:
    """A segment as the service takes it: image observations (pixel envs) packed, others as lists."""
    obs = np.asarray(s.obs)
    images = obs.ndim > 2
    pitch = (
        None if s.pitch is None else [None if not math.isfinite(v) else v for v in np.asarray(s.pitch, float).tolist()]
    )
    return QueryIn(
        query_id=s.query_id,
        start=int(s.start),
        score=float(s.score),
        skill=np.asarray(s.skill, float).reshape(-1).tolist(),
        obs=[] if images else obs.astype(float).tolist(),
        obs_packed=pack_frames(obs.astype(np.uint8)) if images else None,
        xy=np.asarray(s.xy, float).tolist(),
        pitch=pitch,
        qpos=np.asarray(s.qpos, float).tolist(),
        qvel=np.asarray(s.qvel, float).tolist(),
        path_xy=None if s.path_xy is None else np.asarray(s.path_xy, float).tolist(),
        extra=plain(s.extra),
    )


def from_wire(q: QueryRead) -> Segment:
    def arr(values: Any) -> np.ndarray:
        return np.asarray(values, dtype=np.float64)

    return Segment(
        query_id=q.query_id,
        session=q.session,
        epoch=q.epoch,
        skill=arr(q.skill),
        start=q.start,
        obs=unpack_frames(q.obs_packed) if q.obs_packed is not None else arr(q.obs),
        xy=arr(q.xy),
        pitch=arr([math.nan if v is None else v for v in q.pitch])
        if q.pitch is not None
        else np.full(len(q.xy), math.nan),
        qpos=arr(q.qpos),
        qvel=arr(q.qvel),
        score=q.score,
        path_xy=arr(q.path_xy) if q.path_xy is not None else None,
        extra=dict(q.extra),
    )


def adopt(segment: Segment, stored: QueryRead) -> None:
    """The service keeps the segment it stored first; overwrite ours in place with it (the loop
    already holds references to these arrays)."""
    source = from_wire(stored)
    for name in ("obs", "xy", "pitch", "qpos", "qvel", "skill"):
        target = getattr(segment, name)
        value = getattr(source, name)
        if isinstance(target, np.ndarray) and target.shape == value.shape:
            target[...] = value
        else:
            setattr(segment, name, value)
    segment.start, segment.score, segment.epoch = source.start, source.score, source.epoch
    segment.path_xy = source.path_xy


def plain(value: Any) -> Any:
    """JSON-safe copy (numpy → Python; non-finite floats → None)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [plain(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value if value is None or isinstance(value, str | int | float | bool) else str(value)


def flat_numbers(record: dict[str, Any]) -> dict[str, float]:
    """Finite numbers of a metrics record, lists flattened as name[i]; at most MAX_METRICS keys."""
    out: dict[str, float] = {}

    def put(name: str, value: Any) -> None:
        if len(out) >= MAX_METRICS or len(name) > 64:
            return
        if isinstance(value, list | tuple | np.ndarray):
            for i, v in enumerate(np.asarray(value).reshape(-1).tolist()[:16]):
                put(f"{name}[{i}]", v)
        elif isinstance(value, int | float | np.number) and not isinstance(value, bool) and math.isfinite(value):
            out[name] = float(value)

    for key, value in record.items():
        if key != "epoch":
            put(str(key), value)
    return out


def rollouts_of(payload: dict[str, Any], max_points: int = 1000) -> RolloutsIn:
    """{"epoch", "skills": (N, dz), "xy": (N, T, 2), optional "w": (N, T), optional "qpos": (N, T, nq)}
    → at most MAX_ROLLOUTS paths of at most max_points finite points each (evenly thinned;
    millimetres are plenty for a plot); w(s) at the same points goes in each rollout's extra["w"],
    the simulator state at the same points in its qpos (for a 3D replay)."""
    skills = np.asarray(payload.get("skills", []), dtype=float)
    paths = payload.get("xy", [])
    weights = payload.get("w") or []
    states = payload.get("qpos") or []
    rollouts = []
    for i, path in enumerate(paths[:MAX_ROLLOUTS]):
        xy = np.asarray(path, dtype=float).reshape(-1, 2)
        kept = np.flatnonzero(np.isfinite(xy).all(axis=1))
        if len(kept) > min(max_points, MAX_ROLLOUT_POINTS):
            kept = kept[np.linspace(0, len(kept) - 1, min(max_points, MAX_ROLLOUT_POINTS)).round().astype(int)]
        skill = skills[i].reshape(-1) if i < len(skills) else np.zeros(1)
        extra = {}
        if i < len(weights) and len(weights[i]) == len(xy):
            extra["w"] = np.round(np.nan_to_num(np.asarray(weights[i], dtype=float)[kept], nan=1.0), 2).tolist()
        qpos = None
        if i < len(states) and len(states[i]) == len(xy):
            q = np.asarray(states[i], dtype=float)[kept]
            if q.ndim == 2 and q.shape[1] <= MAX_QPOS_WIDTH and np.isfinite(q).all():
                qpos = np.round(q, 4).tolist()
        rollouts.append(
            Rollout(skill=np.nan_to_num(skill).tolist(), xy=np.round(xy[kept], 3).tolist(), qpos=qpos, extra=extra)
        )
    return RolloutsIn(epoch=_epoch(payload) or 0, rollouts=rollouts)


def _epoch(payload: dict[str, Any]) -> int | None:
    epoch = payload.get("epoch")
    return int(epoch) if isinstance(epoch, int | np.integer) and epoch >= 0 else None


def _run_status(status: str, error: Any) -> tuple[RunStatus, str | None]:
    """The loop's words → the service's: "stopped" is a finished run with a message."""
    if status == "stopped":
        return "finished", "stopped by an operator"
    if status in ("training", "waiting_for_labels", "paused", "finished", "failed"):
        return status, (str(error)[:1000] if error else None)  # type: ignore[return-value]
    return "training", f"unknown status {status!r}"
