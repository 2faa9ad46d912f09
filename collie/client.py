"""A small typed, synchronous client for the labeling service, and a resumable stream consumer.

Used by the trainer's HTTP feedback source, the oracle teacher, the labeling UI and the tests. Every
method speaks the wire schemas of collie.schemas. HTTP errors raise ApiError (status and detail),
typed by what a caller does about them: Unauthorized (401/403: a token problem; NotInScope when a
valid token's run is outside its scope, with the typed reason), Conflict (409: the state does not
allow it; NotHolding when a tab's label was refused, with the typed reason), and
Unavailable — Unreachable (no answer; GarbledAnswer: one damaged on the way) or Overloaded (5xx,
429) — the one kind worth retrying, with `retrying` and its Backoff: the one retry policy of every
client (submissions are idempotent by client_request_id, so a retry never labels twice).

Every transport fault httpx raises is one of these (`transport_fault`), never httpx's own: an
answer this client cannot read (a 2xx or 3xx whose body is not the expected JSON, e.g. a proxy's
HTML page) is BadAnswer, and a request that cannot be sent as given (a bad URL, a scheme other
than http(s)) is Unsendable; both are ApiErrors, refusals that asking again does not mend.
httpx's StreamError family (a body read twice) is this module's own bug, left to show as one.
"""

from __future__ import annotations

import functools
import logging
import re
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

import httpx
from pydantic import BaseModel, TypeAdapter, ValidationError

from collie.dashboard_schemas import QueryReview
from collie.schemas import (
    PART_HEADER,
    STREAM_EVENT,
    ClaimRead,
    EffectiveLabel,
    EventPage,
    FeedbackPolicy,
    Health,
    LabelAck,
    LabelerCreate,
    LabelerCreated,
    LabelerRead,
    LabelerScope,
    LabelEventRead,
    LabelledPage,
    LabelledQuery,
    LabelSubmit,
    Me,
    MetricsIn,
    MetricsRead,
    MyLabel,
    NotHeld,
    OutOfScope,
    QualitySettings,
    QueryRead,
    QuerySummary,
    Released,
    Retired,
    RetireRequest,
    Role,
    RolloutsIn,
    RolloutsRead,
    RunCreate,
    RunExtend,
    RunInstructions,
    RunRead,
    RunStatus,
    SessionPost,
    SessionPosted,
    StatusUpdate,
    StreamEvent,
    Submission,
    UndoRequest,
    VotesDiscarded,
)

M = TypeVar("M", bound=BaseModel)
T = TypeVar("T")
log = logging.getLogger(__name__)


class ApiError(Exception):
    """The service answered with an error status (or, for the subclasses below that say so, the
    call cannot be made or read as it is): a refusal, which the same call meets again."""

    def __init__(self, status: int, detail: Any) -> None:
        super().__init__(self.said(status, detail))
        self.status = status
        self.detail = detail

    @staticmethod
    def said(status: int, detail: Any) -> str:
        return f"{status}: {readable(detail)}"


def readable(detail: Any) -> Any:
    """A 422's detail — FastAPI's list of pydantic errors, a dict each — as one line naming each
    field and what is wrong ("run_id: Input should be greater than or equal to 1"); any other
    detail as it is."""
    if not (isinstance(detail, list) and detail and all(isinstance(e, dict) and "msg" in e for e in detail)):
        return detail
    said = []
    for error in detail:
        loc = [str(part) for part in error.get("loc", ())]
        where = ".".join(loc[1:] if loc[:1] in (["body"], ["query"], ["path"], ["header"]) else loc)
        said.append(f"{where}: {error['msg']}" if where else str(error["msg"]))
    return "; ".join(said)


class Unauthorized(ApiError):
    """401 / 403: the token is missing, unknown, revoked, or its role may not do this."""


class Conflict(ApiError):
    """409: the run's or query's state does not allow it (finished run, lease lost, …)."""


class NotHolding(Conflict):
    """409 on a label from a tab that does not hold the query: `refusal.reason` says why."""

    def __init__(self, status: int, refusal: NotHeld) -> None:
        super().__init__(status, refusal.detail)
        self.refusal = refusal


class NotInScope(Unauthorized):
    """403 for a run outside a valid token's scope: `refusal.reason` says why; other runs may be fine."""

    def __init__(self, status: int, refusal: OutOfScope) -> None:
        super().__init__(status, refusal.detail)
        self.refusal = refusal


class Unavailable(Exception):
    """The service cannot answer now; the same call may succeed later (what `retrying` waits out)."""


class Unreachable(Unavailable):
    """No answer from the service (down, restarting, or the network dropped)."""


class GarbledAnswer(Unreachable):
    """An answer damaged on the way: its body is not in the Content-Encoding it declares (a broken
    proxy between; a body cut short is a plain Unreachable). As transient as no answer: the service
    may be fine, and every request the clients retry is safe to send again."""


def unreachable_why(exc: Unreachable) -> str:
    """Why a request got no answer, in a person's words ("connection refused", not httpx's repr)."""
    cause = exc.__cause__
    if isinstance(cause, httpx.TimeoutException):
        limit = timeout_of(cause)
        return f"nothing within {limit:g} s" if limit is not None else "nothing in time"
    text = str(cause or exc)
    return "connection refused" if "Connection refused" in text else text.split("] ", 1)[-1]


TIMEOUT_KINDS = {httpx.ConnectTimeout: "connect", httpx.ReadTimeout: "read", httpx.WriteTimeout: "write"}


def timeout_of(exc: httpx.TimeoutException) -> float | None:
    """The limit that ran out (the client's connect or read timeout, as its request carried it)."""
    try:
        limits = exc.request.extensions.get("timeout", {})
    except RuntimeError:  # an exception raised without its request
        return None
    limit = limits.get(TIMEOUT_KINDS.get(type(exc), ""))
    return float(limit) if isinstance(limit, int | float) else None


def no_answer(exc: Unreachable) -> str:
    """What became of a request without a usable answer, as the rest of a sentence naming the
    service: "does not answer (connection refused)", or that its answer arrived damaged."""
    if isinstance(exc, GarbledAnswer):
        return f"sent an answer damaged on the way, a proxy between? ({exc})"
    return f"does not answer ({unreachable_why(exc)})"


class BadAnswer(ApiError):
    """An answer this client cannot read: a 2xx whose body is not the expected JSON or model (a
    proxy's or another web service's page, a newer collie's), or a redirect (this client follows
    none). `status` is the answer's; the message names the request's URL and what was wrong."""

    @staticmethod
    def said(status: int, detail: Any) -> str:
        return str(detail)


class Unsendable(ApiError):
    """The request cannot be sent as given (an invalid URL, a scheme other than http or https, a
    header HTTP does not allow): nothing was asked (`status` 0), and sending it again fails the same."""

    @staticmethod
    def said(status: int, detail: Any) -> str:
        return str(detail)


# httpx's faults of the request itself, not of the network: every try fails the same way.
UNSENDABLE = (httpx.InvalidURL, httpx.UnsupportedProtocol, httpx.LocalProtocolError)


def transport_fault(exc: httpx.HTTPError | httpx.InvalidURL, method: str, url: str, path: str) -> Exception:
    """The typed error for an httpx fault of a `method` request of `url` (at `path` under the API):
    Unsendable, GarbledAnswer, or Unreachable (any other transport fault: refused, timed out, cut
    off, not HTTP, a proxy that failed); a redirect loop (which a client following no redirects
    never meets) is a BadAnswer."""
    if isinstance(exc, UNSENDABLE):
        return Unsendable(0, f"{method} {url} cannot be sent: {exc}")
    if isinstance(exc, httpx.DecodingError):
        return GarbledAnswer(f"{method} {url}: the body is not in its declared Content-Encoding ({exc})")
    if isinstance(exc, httpx.TooManyRedirects):
        return BadAnswer(0, f"{method} {url}: {exc}")
    return Unreachable(f"{method} {path}: {exc!r}")


# The httpx faults `transport_fault` types: all that a request (not a misuse of httpx) can raise.
TRANSPORT_FAULTS = (httpx.HTTPError, httpx.InvalidURL)


class Overloaded(ApiError, Unavailable):
    """5xx or 429: the service answered that it cannot do it now."""


def answered_error(response: httpx.Response) -> ApiError:
    """The typed error for an error answer; a body with a typed reason (NotHeld, OutOfScope) gives
    its own error, unless it is not one this client knows (a newer service): then the plain one. A
    redirect is a BadAnswer naming where to; a body that is not JSON (a proxy's HTML page) is said
    in one short line."""
    if response.status_code < 400:
        where_to = response.headers.get("Location", "nowhere")
        said = f"{response.status_code}, a redirect to {where_to} (this client follows none: give that address)"
        return BadAnswer(response.status_code, f"{request_said(response)} answered {said}")
    error: Any
    try:
        error = response.json()
        detail = error.get("detail") if isinstance(error, dict) else error
    except ValueError:
        error, detail = None, body_said(response)
    if isinstance(error, dict) and "reason" in error:
        try:
            if response.status_code == 409:
                return NotHolding(409, NotHeld.model_validate(error))
            if response.status_code == 403:
                return NotInScope(403, OutOfScope.model_validate(error))
        except ValidationError:
            pass
    return api_error(response.status_code, detail)


def request_said(response: httpx.Response) -> str:
    return f"{response.request.method} {response.request.url}"


def body_said(response: httpx.Response, limit: int = 120) -> str:
    """A body that is not JSON, in one short line: an HTML page by its title (a proxy's "502 Bad
    Gateway"), other text by its start; an empty one by the status's reason."""
    text = response.text
    kind = response.headers.get("Content-Type", "").split(";")[0].strip()
    if "html" in kind or text.lstrip()[:1] == "<":
        title = re.search(r"<title[^>]*>(.*?)</title>", text, re.IGNORECASE | re.DOTALL)
        shown = " ".join((title.group(1) if title else re.sub(r"<[^>]*>", " ", text)).split())[:60]
        text = f"an HTML page ({shown})"
    text = " ".join(text.split()) or response.reason_phrase or "an empty body"
    return text if len(text) <= limit else text[: limit - 1] + "…"


def bad_answer(response: httpx.Response, exc: ValidationError, expected: str) -> BadAnswer:
    """A 2xx whose body is not the `expected` model: what it was instead, in one line."""
    first = exc.errors(include_url=False)[:3]
    if first and first[0]["type"] == "json_invalid":
        kind = response.headers.get("Content-Type") or "no Content-Type"
        shown = body_said(response)
        got = f"{shown}, not JSON" if shown.startswith("an HTML page") else f"a body that is not JSON ({kind}: {shown})"
    else:
        got = f"JSON that is not {expected} ({readable(first)})"
    return BadAnswer(response.status_code, f"{request_said(response)} answered {response.status_code} with {got}")


def answered(exc: ApiError) -> str:
    """What the service did, after "the service …": "answered 409: …", or for an answer this client
    cannot read or a request it cannot send, "could not be used: …" (their words name the request)."""
    return f"could not be used: {exc}" if isinstance(exc, BadAnswer | Unsendable) else f"answered {exc}"


def api_error(status: int, detail: Any) -> ApiError:
    """The typed error for an error status."""
    if status in (401, 403):
        return Unauthorized(status, detail)
    if status == 409:
        return Conflict(status, detail)
    if status >= 500 or status == 429:
        return Overloaded(status, detail)
    return ApiError(status, detail)


@dataclass(frozen=True)
class Backoff:
    """Exponential backoff: first_s, doubling, at most max_s between tries."""

    first_s: float = 0.1
    max_s: float = 5.0

    def delays(self) -> Iterator[float]:
        delay = self.first_s
        while True:
            yield delay
            delay = min(2 * delay, self.max_s)


def retrying(
    call: Callable[[], T],
    backoff: Backoff = Backoff(),
    attempts: int | None = None,
    stop: threading.Event | None = None,
    what: str = "labeling service",
) -> T:
    """`call()` until it returns: an Unavailable service is waited out with `backoff` (at most
    `attempts` calls; None: until it answers, or until `stop` is set); any other error raises."""
    delays = backoff.delays()
    tries = 0
    while True:
        try:
            return call()
        except Unavailable as exc:
            tries += 1
            if (attempts is not None and tries >= attempts) or (stop is not None and stop.is_set()):
                raise
            delay = next(delays)
            log.warning("%s unavailable (%s); retrying in %.1f s", what, exc, delay)
            if stop is not None:
                stop.wait(delay)
            else:
                time.sleep(delay)


@functools.cache
def _list_of(model: type[M]) -> TypeAdapter[list[M]]:
    return TypeAdapter(list[model])  # type: ignore[valid-type]  # a runtime type argument


def new_request_id() -> str:
    return uuid.uuid4().hex


class CollieClient:
    def __init__(self, api: str, token: str, *, timeout_s: float = 30.0, part: str | None = None) -> None:
        """`part`: sent as PART_HEADER ("trainer": the service notes the run's trainer is alive)."""
        self.api = api.rstrip("/")
        self.token = token
        try:
            self._http = httpx.Client(
                base_url=f"{self.api}/api",
                headers={"Authorization": f"Bearer {token}", **({PART_HEADER: part} if part else {})},
                timeout=httpx.Timeout(timeout_s, connect=5.0),
            )
        except httpx.InvalidURL as exc:
            raise Unsendable(0, f"{self.api} is no URL a request can be sent to: {exc}") from None

    # ---------------------------------------------------------------- plumbing

    def _send(self, method: str, path: str, body: BaseModel | None = None, **kwargs: Any) -> httpx.Response:
        """The answer to `method` `path`, a success (a 2xx); anything else raises its typed error."""
        if body is not None:
            kwargs["content"] = body.model_dump_json()
            kwargs["headers"] = {"Content-Type": "application/json"}
        try:
            response = self._http.request(method, path, **kwargs)
        except TRANSPORT_FAULTS as exc:
            raise transport_fault(exc, method, f"{self.api}/api{path}", path) from exc
        if response.status_code >= 300:  # an error, or a redirect this client does not follow
            raise answered_error(response)
        return response

    def _read(self, model: type[M], response: httpx.Response) -> M:
        try:
            return model.model_validate_json(response.content)
        except ValidationError as exc:
            raise bad_answer(response, exc, model.__name__) from exc

    def _get(self, model: type[M], path: str, **params: Any) -> M:
        clean = {k: v for k, v in params.items() if v is not None}
        return self._read(model, self._send("GET", path, params=clean))

    def _list(self, model: type[M], path: str, **params: Any) -> list[M]:
        clean = {k: v for k, v in params.items() if v is not None}
        response = self._send("GET", path, params=clean)
        try:
            return _list_of(model).validate_json(response.content)
        except ValidationError as exc:
            raise bad_answer(response, exc, f"a list of {model.__name__}") from exc

    def _post(self, model: type[M], path: str, body: BaseModel | None = None, **params: Any) -> M:
        clean = {k: v for k, v in params.items() if v is not None}
        return self._read(model, self._send("POST", path, body, params=clean))

    def _put(self, model: type[M], path: str, body: BaseModel) -> M:
        return self._read(model, self._send("PUT", path, body))

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> CollieClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    # ---------------------------------------------------------------- who and health

    def health(self) -> Health:
        return self._get(Health, "/health")

    def me(self) -> Me:
        return self._get(Me, "/me")

    def create_labeler(self, name: str, role: Role = "labeler", runs: list[int] | None = None) -> LabelerCreated:
        """A new principal and its token; `runs` limits a labeler to those runs."""
        return self._post(LabelerCreated, "/labelers", LabelerCreate(name=name, role=role, runs=runs))

    def labelers(self) -> list[LabelerRead]:
        return self._list(LabelerRead, "/labelers")

    def revoke(self, labeler_id: int) -> LabelerRead:
        return self._read(LabelerRead, self._send("DELETE", f"/labelers/{labeler_id}"))

    def set_labeler_runs(self, labeler_id: int, runs: list[int] | None) -> LabelerRead:
        """Limit a labeler to `runs` from now on; None: every run."""
        body = LabelerScope(runs=runs)
        return self._put(LabelerRead, f"/labelers/{labeler_id}/runs", body)

    # ---------------------------------------------------------------- runs and control

    def create_run(self, spec: RunCreate) -> RunRead:
        return self._post(RunRead, "/runs", spec)

    def runs(self, status: RunStatus | None = None, limit: int = 100, offset: int = 0) -> list[RunRead]:
        return self._list(RunRead, "/runs", status=status, limit=limit, offset=offset)

    def run(self, run_id: int) -> RunRead:
        return self._get(RunRead, f"/runs/{run_id}")

    def set_status(
        self, run_id: int, status: RunStatus, epoch: int | None = None, message: str | None = None
    ) -> RunRead:
        body = StatusUpdate(status=status, epoch=epoch, message=message)
        return self._put(RunRead, f"/runs/{run_id}/status", body)

    def extend(self, run_id: int, epochs_total: int) -> RunRead:
        """More epochs for the run; a finished run reopens (409 for one stopped by an operator or failed)."""
        body = RunExtend(epochs_total=epochs_total)
        return self._post(RunRead, f"/runs/{run_id}/extend", body)

    def pause(self, run_id: int) -> RunRead:
        return self._post(RunRead, f"/runs/{run_id}/pause")

    def resume(self, run_id: int) -> RunRead:
        return self._post(RunRead, f"/runs/{run_id}/resume")

    def stop(self, run_id: int) -> RunRead:
        return self._post(RunRead, f"/runs/{run_id}/stop")

    def set_feedback_policy(self, run_id: int, timeout_s: float | None) -> RunRead:
        """The trainer continues after timeout_s seconds of a session with what arrived (None: waits
        for every label); applies to the session it is waiting on now."""
        return self._post(RunRead, f"/runs/{run_id}/feedback-policy", FeedbackPolicy(timeout_s=timeout_s))

    def set_quality(self, run_id: int, redundancy: int | None = None, gold_rate: float | None = None) -> RunRead:
        """Labeler quality control (operator): labels from distinct labelers per query, and the
        share of each labeler's segments that are gold (None: the run's value stays)."""
        body = QualitySettings(redundancy=redundancy, gold_rate=gold_rate)
        return self._put(RunRead, f"/runs/{run_id}/quality", body)

    def set_instructions(self, run_id: int, text: str) -> RunRead:
        """An operator's free-text instructions for the run's labelers ("" clears them)."""
        body = RunInstructions(text=text)
        return self._put(RunRead, f"/runs/{run_id}/instructions", body)

    # ---------------------------------------------------------------- queries

    def post_session(self, run_id: int, session: SessionPost) -> SessionPosted:
        return self._post(SessionPosted, f"/runs/{run_id}/sessions", session)

    def retire(self, run_id: int, query_ids: list[str]) -> Retired:
        return self._post(Retired, f"/runs/{run_id}/retire", RetireRequest(query_ids=query_ids))

    def queries(
        self,
        run_id: int,
        session: int | None = None,
        status: str | None = None,
        limit: int = 1000,
        offset: int = 0,
    ) -> list[QuerySummary]:
        return self._list(
            QuerySummary,
            f"/runs/{run_id}/queries",
            session=session,
            status=status,
            limit=limit,
            offset=offset,
        )

    def query(self, run_id: int, query_id: str) -> QueryRead:
        return self._get(QueryRead, f"/runs/{run_id}/queries/{query_id}")

    def query_review(self, run_id: int, query_id: str) -> QueryReview:
        """One query's segment and labels by labeler, for an operator's review (operators only)."""
        return self._get(QueryReview, f"/dashboard/runs/{run_id}/queries/{query_id}/review")

    def claim(
        self, run_id: int, lease_s: float | None = None, hold: int = 1, tab: str | None = None
    ) -> ClaimRead | None:
        """The next query under a lease, or None when nothing is claimable right now. With hold=2 a
        second query is taken besides the one held (to preload it); every held lease is renewed.
        With a `tab`, the claim is that tab's: it sees only the queries held for it."""
        params: dict[str, float | int | str] = {"lease_s": lease_s} if lease_s is not None else {}
        if hold != 1:
            params["hold"] = hold
        if tab is not None:
            params["tab"] = tab
        response = self._send("POST", f"/runs/{run_id}/claim", params=params)
        return None if response.status_code == 204 else self._read(ClaimRead, response)

    def labelled(self, run_id: int, page_size: int = 200) -> Iterator[LabelledQuery]:
        """Every query with an effective label, with frames (paged)."""
        cursor: int | None = 0
        while cursor is not None:
            page = self._get(LabelledPage, f"/runs/{run_id}/labelled", cursor=cursor, limit=page_size)
            yield from page.items
            cursor = page.next_cursor

    # ---------------------------------------------------------------- labels

    def submit(
        self,
        run_id: int,
        query_id: str,
        value: Submission,
        seconds: float | None = None,
        client_request_id: str | None = None,
        next: bool = False,
        tab: str | None = None,
        hold: int = 1,
        lease_s: float | None = None,
    ) -> LabelAck:
        """Label (0 bad, 1 neutral, 2 good) or "skip". Pass the same client_request_id to retry safely.
        With next=True the answer also carries the labeler's next claimed query (ack.next; with hold=2
        the second they hold: the one to preload, taken in the label's transaction), its leases
        renewed for `lease_s` (None: the service's). With a `tab`, only that tab's claim may be
        labelled (NotHolding otherwise), and never as a revision."""
        body = LabelSubmit(
            query_id=query_id,
            value=value,
            seconds=seconds,
            client_request_id=client_request_id or new_request_id(),
            tab=tab,
        )
        params = {"next": "true", "hold": hold if hold != 1 else None, "lease_s": lease_s} if next else {}
        return self._post(LabelAck, f"/runs/{run_id}/labels", body, **params)

    def release(self, run_id: int, query_id: str) -> Released:
        """Hand a held query back to the pool (records nothing, unlike a skip)."""
        return self._post(Released, f"/runs/{run_id}/queries/{query_id}/release", None)

    def skip(self, run_id: int, query_id: str, client_request_id: str | None = None) -> LabelAck:
        return self.submit(run_id, query_id, "skip", client_request_id=client_request_id)

    def undo(
        self,
        run_id: int,
        query_id: str,
        client_request_id: str | None = None,
        tab: str | None = None,
        lease_s: float | None = None,
    ) -> LabelAck:
        """Withdraw the caller's label; it comes back to them (to `tab`) under a fresh lease of
        `lease_s` (None: the service's)."""
        body = UndoRequest(query_id=query_id, client_request_id=client_request_id or new_request_id(), tab=tab)
        return self._post(LabelAck, f"/runs/{run_id}/undo", body, lease_s=lease_s)

    def discard_votes(self, run_id: int, labeler_id: int) -> VotesDiscarded:
        """Operator: withdraw every label one labeler gave in the run."""
        return self._post(VotesDiscarded, f"/runs/{run_id}/labelers/{labeler_id}/discard")

    def label_events(self, run_id: int, after: int = 0, limit: int = 1000) -> list[LabelEventRead]:
        return self._list(LabelEventRead, f"/runs/{run_id}/labels", after=after, limit=limit)

    def my_labels(self, run_id: int) -> list[MyLabel]:
        """The caller's labels in the run, newest first (a labeler's review panel)."""
        return self._list(MyLabel, f"/runs/{run_id}/labels/mine")

    def effective_labels(self, run_id: int) -> list[EffectiveLabel]:
        return self._list(EffectiveLabel, f"/runs/{run_id}/labels/effective")

    def export(self, run_id: int, fmt: str = "json", effective: bool = False) -> str:
        params = {"format": fmt, "effective": str(effective).lower()}
        return self._send("GET", f"/runs/{run_id}/export", params=params).text

    # ---------------------------------------------------------------- rollouts and metrics

    def post_metrics(self, run_id: int, metrics: MetricsIn) -> MetricsRead:
        return self._post(MetricsRead, f"/runs/{run_id}/metrics", metrics)

    def metrics(self, run_id: int, after_epoch: int | None = None, limit: int = 1000) -> list[MetricsRead]:
        return self._list(MetricsRead, f"/runs/{run_id}/metrics", after_epoch=after_epoch, limit=limit)

    def post_rollouts(self, run_id: int, rollouts: RolloutsIn) -> RolloutsRead:
        return self._post(RolloutsRead, f"/runs/{run_id}/rollouts", rollouts)

    def rollouts(self, run_id: int, limit: int = 5) -> list[RolloutsRead]:
        return self._list(RolloutsRead, f"/runs/{run_id}/rollouts", limit=limit)

    # ---------------------------------------------------------------- stream

    def events(self, run_id: int, after: int = 0, wait_s: float = 0.0, limit: int = 1000) -> EventPage:
        """Events after `after`; waits up to wait_s for the first one (long poll)."""
        timeout = httpx.Timeout(wait_s + 30.0, connect=5.0)
        response = self._send(
            "GET",
            f"/runs/{run_id}/events",
            params={"after": after, "wait_s": wait_s, "limit": limit},
            timeout=timeout,
        )
        return self._read(EventPage, response)

    def stream(self, run_id: int, after: int = 0, max_backoff_s: float = 5.0) -> EventStream:
        return EventStream(self, run_id, after, max_backoff_s)


class EventStream:
    """A run's Server-Sent Events as an iterator of StreamEvent. A dropped connection, a service
    restart, a busy service (5xx, 429) or an answer damaged on the way is retried with the shared
    Backoff (0.1 s doubling up to max_backoff_s) and resumed from the last id seen, so nothing is
    missed and nothing is yielded twice. A refusal ends it with its typed error: 4xx errors, and a
    BadAnswer for an answer that is no event stream (another page, an event this client cannot
    read), which reconnecting would only fetch again."""

    def __init__(self, client: CollieClient, run_id: int, after: int = 0, max_backoff_s: float = 5.0) -> None:
        self.client = client
        self.run_id = run_id
        self.last_id = after
        self.max_backoff_s = max_backoff_s
        self.reconnects = 0
        self._closed = False

    def close(self) -> None:
        self._closed = True

    def __iter__(self) -> Iterator[StreamEvent]:
        backoff = Backoff(max_s=self.max_backoff_s)
        delays = backoff.delays()
        while not self._closed:
            try:
                yield from self._connection()
                delays = backoff.delays()  # a clean end (server shutdown): reconnect promptly
            except Unavailable as exc:  # no answer, dropped or damaged while reading, or busy
                log.info("event stream of run %s: %s; reconnecting", self.run_id, exc)
                time.sleep(next(delays))
            self.reconnects += 1

    def _connection(self) -> Iterator[StreamEvent]:
        path = f"/runs/{self.run_id}/stream"
        try:
            yield from self._events(path)
        except TRANSPORT_FAULTS as exc:
            raise transport_fault(exc, "GET", f"{self.client.api}/api{path}", path) from exc

    def _events(self, path: str) -> Iterator[StreamEvent]:
        headers = {"Last-Event-ID": str(self.last_id), "Accept": "text/event-stream"}
        timeout = httpx.Timeout(5.0, read=45.0)  # the server sends a heartbeat every 15 s
        with self.client._http.stream("GET", path, headers=headers, timeout=timeout) as r:
            if r.status_code >= 300:
                r.read()
                raise answered_error(r)
            if not r.headers.get("Content-Type", "").startswith("text/event-stream"):  # e.g. a proxy's page
                r.read()
                said = f"{r.status_code} with {r.headers.get('Content-Type') or 'no Content-Type'}, not an event stream"
                raise BadAnswer(r.status_code, f"{request_said(r)} answered {said} ({body_said(r)})")
            data: list[str] = []
            for line in r.iter_lines():
                if self._closed:
                    return
                if line.startswith("data:"):
                    data.append(line[5:].lstrip())
                elif not line and data:
                    event = self._event(r, "\n".join(data))
                    data = []
                    if event.id > self.last_id:
                        self.last_id = event.id
                        yield event

    @staticmethod
    def _event(response: httpx.Response, data: str) -> StreamEvent:
        try:
            return STREAM_EVENT.validate_json(data)
        except ValidationError as exc:
            said = readable(exc.errors(include_url=False)[:3])
            raise BadAnswer(
                response.status_code, f"{request_said(response)} sent an event this client cannot read ({said})"
            ) from exc
