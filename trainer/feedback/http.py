"""Labels from the labeling service, over HTTP (Algorithm 1, lines 5–7, with people in the loop).

The trainer's side of the contract (docs/service.md):
- `collect` posts the session's segments in one call, marks the run waiting_for_labels and reads
  the run's event log (long poll, resumable by event id) until every segment of the session has an
  effective label — or, with `timeout_s`, until that many seconds passed (then it goes on with what
  arrived; later labels come through `revisions`). An operator may change `timeout_s` at any time
  (a "policy" event): the session being waited on is then re-timed from its start, so a shorter
  timeout that has already passed releases it at once, and None waits for every label again.
  A stop raises StopRequested, as does a signal to the trainer (`interrupt`) at the wait's next
  call to the service; while paused it keeps waiting and does not return.
- Every label the trainer is given is remembered with its value, so a label reaches the trainer
  once, and a change of it (undo, relabel, a late label) once more as a revision.
- `history` returns the labelled segments of the run for a restarted trainer, which replays from
  its checkpoint. A session is identified by its schedule position (`session`): re-posting one
  already posted (the replay reaches it again) stores nothing; `collect` then replaces the given
  segments, in place in the list, by the stored session's and waits only for the labels it still
  lacks. Unlabelled leftovers of earlier sessions whose segments the checkpoint holds
  (`history(held=)`) stay open, their late labels coming as revisions; those it does not hold are
  retired on the service, so a label the trainer cannot use is never taken.
- A segment id the service already holds in a new session keeps the stored segment: `collect`
  copies the stored arrays into the given segment in place.
- The service going away (restart, network) is waited out with backoff; `control` never blocks
  training for long and never raises. Telemetry goes through `reporter` (an HttpReporter for the
  same run), which the trainer's command hands to the loop.
numpy only: no torch here, and no database — only HTTP.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import time
from collections.abc import Callable, Collection
from typing import Any, Literal, TypeVar

import numpy as np

from collie import startup
from collie.client import (
    ApiError,
    Backoff,
    BadAnswer,
    CollieClient,
    Conflict,
    Overloaded,
    Unauthorized,
    Unavailable,
    Unreachable,
    Unsendable,
    retrying,
)
from collie.frames import pack_frames, unpack_frames
from collie.labels import Label
from collie.schemas import (
    ControlEvent,
    EventPage,
    LabelChangedEvent,
    PolicyEvent,
    QueryIn,
    QueryRead,
    RunCreate,
    RunRead,
    RunStatus,
    SessionPost,
    StreamEvent,
    WithdrawnEvent,
)
from trainer.feedback.base import FeedbackSource, LabelEvent, Segment, SourceRefused, StopRequested
from trainer.feedback.http_reporter import HttpReporter
from trainer.telemetry import StatusReport

log = logging.getLogger(__name__)
events_page_size = 1000  # the service's largest page
T = TypeVar("T")
CREATE_ATTEMPTS = 8  # a busy (503, 429) or silent service is asked again for about 10 s (the shared backoff)


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
        self.client = CollieClient(api, token, part="trainer")
        self.reporter = HttpReporter(api, token, run_id, timeout_s=report_timeout_s)  # the run's telemetry
        self._after = 0  # last event id applied from the run's log
        self._labels: dict[str, Label | None] = {}  # effective labels, as the log says
        self._given: dict[str, Label | None] = {}  # what the trainer was handed, per known query
        self._changed: set[str] = set()  # queries whose label moved since the last revisions()
        self._control: Literal["run", "pause", "stop"] = "run"
        self._swept = False  # leftovers of sessions before the first collect retired?

    @classmethod
    def create(cls, api: str, token: str, spec: RunCreate, **kwargs: Any) -> HttpFeedback:
        """Create the run on the service and return a source for it (timeout_s defaults to the
        spec's feedback_timeout_s). A busy service's 503 or 429 (nothing stored) is waited out; so
        is an unanswered request when the spec has a client_request_id (a repeat answers the run
        the first made), never without one, which might make the run twice."""
        kwargs.setdefault("timeout_s", spec.feedback_timeout_s)
        transient = Overloaded if spec.client_request_id is None else Unavailable
        with CollieClient(api, token) as client:
            delays = Backoff().delays()
            for _ in range(CREATE_ATTEMPTS - 1):
                with contextlib.suppress(transient):
                    run = client.create_run(spec)
                    break
                time.sleep(next(delays))
            else:
                run = client.create_run(spec)
        return cls(api, token, run.id, **kwargs)

    def held_run(self) -> RunRead:
        """The run as the service holds it, waiting out a restart or a busy database."""
        return self._retry(lambda: self.client.run(self.run_id))

    def extend_to(self, epochs: int) -> str | None:
        """More epochs than the service's run has (a resumed trainer given a larger --epochs): a
        finished run reopens for them. One an operator stopped, or one that failed, stays ended:
        then the words saying so."""
        held = self.held_run()
        if epochs <= (held.epochs_total or 0):
            return None
        if held.control == "stop" or held.status == "failed":
            how = "was stopped by an operator" if held.control == "stop" else "failed"
            return f"run {self.run_id} {how}: it is not extended to {epochs} epochs"
        self._retry(lambda: self.client.extend(self.run_id, epochs))
        return None

    # ---------------------------------------------------------------- the interface

    def collect(self, session: int, epoch: int, segments: list[Segment]) -> list[LabelEvent]:
        if self._control == "stop":  # e.g. resumed in the wait an operator stopped: the run takes no session
            raise StopRequested(f"run {self.run_id} was stopped by an operator")
        if not self._swept:
            self._retire_leftovers(before_session=session)
            self._swept = True
        body = SessionPost(session=session, epoch=epoch, queries=[to_wire(s) for s in segments])
        try:
            posted = self._retry(lambda: self.client.post_session(self.run_id, body))
        except Conflict as exc:  # an operator stopped the run since we last looked: it takes no session, we end
            self._pump(0.0)
            if self._control == "stop":
                raise StopRequested(f"run {self.run_id} was stopped by an operator") from None
            # e.g. past the run's budget (n_total): asking again would be refused again
            raise SourceRefused(
                f"the labeling service refused session {session} of run {self.run_id} ({exc})", ""
            ) from None
        startup.mark("segments posted", epoch)
        startup.done()  # the start is over once a segment is out
        if posted.reused:  # this position was posted before (a resumed trainer): its queries, not new ones
            stored = [self._retry(functools.partial(self.client.query, self.run_id, q)) for q in posted.query_ids]
            given = {s.query_id: s for s in segments}
            for q in stored:  # a segment under a stored id is overwritten in place (callers may hold its arrays)
                if q.query_id in given:
                    adopt(given[q.query_id], q)
            segments[:] = [given.get(q.query_id) or from_wire(q) for q in stored]
            ids = [q.query_id for q in stored if q.status != "retired"]  # closed ones will get no label
        else:
            by_id = {s.query_id: s for s in segments}
            for query_id in posted.existing:
                adopt(by_id[query_id], self._retry(functools.partial(self.client.query, self.run_id, query_id)))
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
        except Unauthorized as exc:  # raised at the epoch's end (control), where a checkpoint resumes exactly
            self.refusal = self._refusal(exc)
            return []
        except (Unreachable, ApiError) as exc:
            log.warning("labeling service unreachable, revisions wait: %s", exc)
            return []
        return self._hand_over([q for q in self._changed if q in self._given])

    def control(self, epoch: int | None = None) -> Literal["run", "pause", "stop"]:
        try:
            self._pump(0.0, patient=False)
        except Unauthorized as exc:
            self.refusal = self._refusal(exc)
        except (Unreachable, ApiError) as exc:
            log.warning("labeling service unreachable, keeping control=%s: %s", self._control, exc)
        if self.refusal is not None:
            raise self.refusal
        if self._control == "pause":  # with the epoch: a status without one is stamped with the run's last
            self._show("paused", epoch)
        elif self.reporter.shown == "paused":
            self._show("training", epoch)
        return self._control

    def history(self, held: Collection[str] = ()) -> list[tuple[Segment, int]]:
        """Every labelled segment of the run, once each (the trainer rebuilds D0/D1/D2 from it)."""
        self._pump(0.0)
        items = self._retry(lambda: list(self.client.labelled(self.run_id)))
        result = []
        for item in items:
            self._given[item.query.query_id] = item.label
            self._changed.discard(item.query.query_id)
            result.append((from_wire(item.query), int(item.label)))
        for query_id in held:  # unlabelled but held (a session the trainer left on its timeout): late
            self._given.setdefault(query_id, None)  # labels come as revisions, and it is no leftover to retire
        return result  # leftovers stay open: the resumed loop replays their sessions and waits for them

    def close(self) -> None:
        self.client.close()
        self.reporter.close()

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

    def _apply(self, events: list[StreamEvent]) -> None:
        for event in events:
            if isinstance(event, LabelChangedEvent | WithdrawnEvent):
                self._labels[event.data.query_id] = event.data.label
                self._changed.add(event.data.query_id)
            elif isinstance(event, ControlEvent):
                self._control = event.data.control
            elif isinstance(event, PolicyEvent):
                self.timeout_s = event.data.timeout_s
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
        if status != self.reporter.shown:
            self.reporter.status(StatusReport(status, epoch))

    def _retry(self, call: Callable[[], T]) -> T:
        """Call until the service answers: waits out restarts (and answers damaged on the way) with
        backoff; 4xx errors raise, a refused token, an answer the client cannot read (BadAnswer: a
        proxy's page) or a request it cannot send as SourceRefused, which ends the run checkpointed.
        Once interrupted (`interrupt`), the next attempt raises StopRequested instead: no session is
        posted after a signal, and a wait on an unreachable service ends too."""

        def attempt() -> T:
            if self.interrupted is not None:
                raise StopRequested(self.interrupted)
            return call()

        try:
            return retrying(attempt, Backoff(max_s=self.max_backoff_s))
        except Unauthorized as exc:
            raise self._refusal(exc) from None
        except (BadAnswer, Unsendable) as exc:  # asking again gets the same: one line, not a traceback
            raise SourceRefused(f"the labeling service could not be used for run {self.run_id}: {exc}", "") from None

    def _refusal(self, exc: Unauthorized) -> SourceRefused:
        return SourceRefused(f"the labeling service refused the trainer's token for run {self.run_id} ({exc})")


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
