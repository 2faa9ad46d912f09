"""One labeler's link to the labeling service: which run to label, claims, labels, undo, progress.

Everything goes through collie.client over HTTP. Errors are sorted into what the page must say:
a refused token (AuthRefused), a service that does not answer or whose answer arrived damaged
(ServiceDown, retried by the caller), or a submission the service would not take (Rejected; also
an answer this UI cannot read, e.g. a proxy's page, said in one line naming its URL).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from collie.client import (
    ApiError,
    Backoff,
    CollieClient,
    GarbledAnswer,
    NotHolding,
    NotInScope,
    Overloaded,
    Unauthorized,
    Unreachable,
    retrying,
)
from collie.dashboard_schemas import QueryReview
from collie.schemas import (
    FINISHED,
    MAX_HOLD,
    ClaimRead,
    EventPage,
    LabelAck,
    Me,
    MetricsRead,
    MyLabel,
    NotHeldReason,
    QueryRead,
    RolloutsRead,
    RunRead,
    Submission,
)

__all__ = ["AuthRefused", "MyLabel", "Progress", "Rejected", "ServiceDown", "ServiceLink", "is_open"]

T = TypeVar("T")


class AuthRefused(Exception):
    """The token is missing, unknown, revoked, or not allowed to label."""


class ServiceDown(Exception):
    """The service did not answer (down, restarting, network)."""


class Rejected(Exception):
    """The service answered but would not do it (conflict, gone, invalid)."""


# Why the service refused this tab's label (collie.schemas.NotHeld), in the labeler's words.
NOT_HELD: dict[NotHeldReason, str] = {
    "other_tab": "another of your tabs holds it now",
    "other_labeler": "its claim ran out and another labeler took it",
    "labelled_by_you": "you labelled it already, in another tab or window (relabel it from My labels)",
    "labelled": "someone else labelled it",
    "retired": "the trainer withdrew it",
    "not_claimed": "its claim ended",
}


@dataclass(frozen=True)
class Progress:
    session: int
    session_done: int  # k: queries of this feedback session with an effective label
    session_size: int  # M
    total_done: int  # n: labels in the run
    total_planned: int | None  # N_total (the run's label budget), when the trainer gave one
    instructions: str = ""  # the operator's for this run, as they are now
    redundancy: int = 1  # labels from distinct labelers before a query counts (session_done counts those)
    paused: bool = False  # an operator paused the run: labels still count, the trainer waits


class ServiceLink:
    """Calls for one labeler token. Submissions are retried with the same client_request_id, so a
    retry after a dropped answer never labels twice."""

    def __init__(
        self, api: str, token: str, run_id: int | None = None, lease_s: float = 60.0, tab: str | None = None
    ) -> None:
        self.api = api
        self.client = CollieClient(api, token, timeout_s=10.0)
        self.pinned_run = run_id
        self.lease_s = lease_s
        self.tab = tab  # the browser tab's id: claims are this tab's, and the service labels only those

    def close(self) -> None:
        self.client.close()

    def _call(self, fn: Callable[[], T]) -> T:
        try:
            return fn()
        except GarbledAnswer as exc:
            raise ServiceDown(f"the labeling service at {self.api} sent an answer damaged on the way ({exc})") from exc
        except Unreachable as exc:
            raise ServiceDown(f"the labeling service at {self.api} does not answer") from exc
        except Overloaded as exc:
            raise ServiceDown(f"the labeling service failed ({exc.status}): {exc.detail}") from exc
        except NotInScope as exc:  # a valid token, taken off that run: the tab moves on
            raise Rejected(exc.refusal.detail) from exc
        except Unauthorized as exc:
            raise AuthRefused(str(exc.detail)) from exc
        except NotHolding as exc:
            refusal = exc.refusal
            raise Rejected(f"this tab no longer holds segment {refusal.query_id}: {NOT_HELD[refusal.reason]}") from exc
        except ApiError as exc:  # BadAnswer and Unsendable too: their detail is the whole line
            raise Rejected(str(exc.detail)) from exc

    def login(self) -> Me:
        me = self._call(self.client.me)
        if me.role not in ("labeler", "operator"):
            raise AuthRefused(f"this is a {me.role} token; labeling needs a labeler token")
        return me

    def pick_run(self) -> RunRead | None:
        """The run to label: the pinned one, else the newest open run with pending queries, else the
        newest open run (to wait on)."""
        if self.pinned_run is not None:
            return self._call(lambda: self.client.run(self.pinned_run))  # type: ignore[arg-type]  # not None in this branch
        runs = [r for r in self._call(lambda: self.client.runs(limit=50)) if is_open(r)]
        runs.sort(key=lambda r: r.id, reverse=True)
        with_work = [r for r in runs if r.queue.pending > 0]
        return (with_work or runs)[0] if runs else None

    def run(self, run_id: int) -> RunRead:
        return self._call(lambda: self.client.run(run_id))

    def claim(self, run_id: int, hold: int = 1) -> ClaimRead | None:
        """The next query under a lease (or the newest this labeler holds); every lease they hold
        is renewed. hold=2 takes a second query to preload besides the one on screen."""
        return self._call(lambda: self.client.claim(run_id, lease_s=self.lease_s, hold=hold, tab=self.tab))

    def submit(
        self,
        run_id: int,
        query_id: str,
        value: Submission,
        seconds: float | None,
        request_id: str,
        revision: bool = False,
        preload: bool = False,
    ) -> LabelAck:
        """Label or skip; `request_id` makes a repeat of the same key press harmless. A first label
        names this tab, so the service refuses it (Rejected, saying why) unless this tab holds the
        segment; a revision of one's own label needs no claim. With `preload`, the answer's `next`
        is the segment to preload, claimed in the label's own transaction (no second round trip)."""
        tab, next = (None, False) if revision else (self.tab, preload)
        return self._retrying(
            lambda: self.client.submit(
                run_id,
                query_id,
                value,
                seconds,
                request_id,
                next=next,
                tab=tab,
                hold=MAX_HOLD if next else 1,
                lease_s=self.lease_s,
            )
        )

    def undo(self, run_id: int, query_id: str, request_id: str) -> LabelAck:
        """Withdraw one's label; the segment comes back to this tab under a fresh claim."""
        return self._retrying(
            lambda: self.client.undo(run_id, query_id, client_request_id=request_id, tab=self.tab, lease_s=self.lease_s)
        )

    def release(self, run_id: int, query_id: str) -> None:
        """Hand a held query back to the pool (nothing is recorded: it was never judged)."""
        self._call(lambda: self.client.release(run_id, query_id))

    def progress(self, run_id: int, session: int) -> Progress:
        run = self._call(lambda: self.client.run(run_id))
        queries = self._call(lambda: self.client.queries(run_id, session=session, limit=5000))
        done = sum(1 for q in queries if q.label is not None)
        return Progress(
            session, done, len(queries), run.n_labels, run.n_total, run.instructions, run.redundancy,
            run.control == "pause",
        )  # fmt: skip

    def latest_rollouts(self, run_id: int) -> RolloutsRead | None:
        """The run's newest evaluation rollouts (with simulator states, when the trainer sent them)."""
        found = self._call(lambda: self.client.rollouts(run_id, limit=1))
        return found[-1] if found else None

    def events(self, run_id: int, after: int, wait_s: float) -> EventPage:
        return self._call(lambda: self.client.events(run_id, after=after, wait_s=wait_s, limit=1000))

    def wait_for_events(self, run_id: int, after: int, wait_s: float) -> EventPage:
        """Block up to wait_s for anything new on the run's stream."""
        return self._call(lambda: self.client.events(run_id, after=after, wait_s=wait_s, limit=100))

    def query(self, run_id: int, query_id: str) -> QueryRead:
        return self._call(lambda: self.client.query(run_id, query_id))

    def review(self, run_id: int, query_id: str) -> QueryReview:
        """One query's segment and labels by labeler, for an operator's review (operators only)."""
        return self._call(lambda: self.client.query_review(run_id, query_id))

    def my_labels(self, run_id: int) -> list[MyLabel]:
        """This labeler's labels in the run, newest first (the service keeps them: they survive reloads)."""
        return self._call(lambda: self.client.my_labels(run_id))

    def metrics(self, run_id: int, last: int = 20) -> list[MetricsRead]:
        """The trainer's latest metrics (their timestamps give its epoch rate)."""
        return self._call(lambda: self.client.metrics(run_id, limit=last))

    def _retrying(self, fn: Callable[[], T], attempts: int = 4) -> T:
        """A few tries with the shared backoff (a labeler waits for the answer), then ServiceDown."""
        return self._call(lambda: retrying(fn, Backoff(first_s=0.25, max_s=2.0), attempts=attempts))


def is_open(run: RunRead) -> bool:
    return run.status not in FINISHED and run.control != "stop"
