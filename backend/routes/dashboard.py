"""The operators' dashboard API: read-only views for web/ (any role may read them, but for one
query's review, which names who labelled what: operators only; run control stays with
/api/runs/{id}/pause|resume|stop, operators only).

- GET /dashboard/runs — the runs list, as a long poll (?after=VERSION&wait_s=S answers as soon as
  any run's log grows): the page keeps one request open, as the trainer does with /events;
- GET /dashboard/runs/{id} — the whole run page in one read, with the stream id to follow it from;
- GET /dashboard/runs/{id}/metrics — the metric history, thinned to at most max_points rows;
- GET /dashboard/runs/{id}/labeling — the labeling panel and labelled states, after label events;
- GET /dashboard/runs/{id}/queries/{query_id}/review — one query's segment and labels by labeler,
  for the labeling UI's review mode (the disagreement list's "replay in 3D").
"""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response
from pydantic import BaseModel

from backend.routes.deps import DB, AnyCaller, OperatorCaller, RunId
from backend.services import dashboard, review
from backend.services.label_stats import SegmentCache
from collie.dashboard_schemas import (
    DEFAULT_HISTORY_POINTS,
    MAX_HISTORY_POINTS,
    LabelingView,
    MetricHistory,
    QueryReview,
    RunDashboard,
    RunsPage,
)
from collie.schemas import MAX_INT, QueryId

router = APIRouter(prefix="/dashboard", tags=["dashboard"])

POLL_S = 0.25  # how often a waiting runs request looks for news (one indexed max())
Points = Annotated[int, Query(ge=2, le=MAX_HISTORY_POINTS)]
RunsLimit = Annotated[int, Query(ge=1, le=1000)]


async def segment_cache(request: Request) -> SegmentCache:
    state = request.app.state
    if getattr(state, "dashboard_segments", None) is None:
        state.dashboard_segments = SegmentCache()
    return state.dashboard_segments


Cache = Annotated[SegmentCache, Depends(segment_cache)]


@router.get("/runs")
async def list_runs(
    request: Request,
    caller: AnyCaller,
    db: DB,
    limit: RunsLimit = 100,
    after: Annotated[int, Query(ge=0, le=MAX_INT, description="the version last seen")] = 0,
    wait_s: Annotated[
        float, Query(ge=0, le=60, allow_inf_nan=False, description="wait this long for a newer version")
    ] = 0.0,
) -> RunsPage:
    """The newest runs. A long poll: with wait_s, answers as soon as any run's log grows past
    version `after`, else after wait_s (lease counts change without a version)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    hub = request.app.state.hub  # closed when the service stops: the page is answered then, not cancelled
    while True:
        with db.read() as conn:
            version = dashboard.latest_event_id(conn)
        if version != after or loop.time() >= deadline or hub.closed or await request.is_disconnected():
            break
        await asyncio.sleep(min(POLL_S, max(0.0, deadline - loop.time())))

    def page() -> RunsPage:
        with db.read() as conn:
            return RunsPage(version=dashboard.latest_event_id(conn), runs=dashboard.summaries(conn, limit, caller.runs))

    return await asyncio.to_thread(page)


def as_json(model: BaseModel) -> Response:
    """Serialised once (FastAPI would dump, validate and serialise a returned model again)."""
    return Response(model.model_dump_json(), media_type="application/json")


@router.get("/runs/{run_id}", response_model=RunDashboard)
def run_page(
    run_id: RunId, caller: AnyCaller, db: DB, cache: Cache, max_points: Points = DEFAULT_HISTORY_POINTS
) -> Response:
    """The run page; a labeler's has no disagreements (they name other labelers' votes)."""
    with db.read() as conn:
        return as_json(dashboard.run_page(conn, run_id, max_points, cache, votes=caller.role != "labeler"))


@router.get("/runs/{run_id}/metrics", response_model=MetricHistory)
def metric_history(run_id: RunId, _: AnyCaller, db: DB, max_points: Points = DEFAULT_HISTORY_POINTS) -> Response:
    with db.read() as conn:
        return as_json(dashboard.metric_history(conn, run_id, max_points))


@router.get("/runs/{run_id}/labeling")
def labeling(run_id: RunId, caller: AnyCaller, db: DB, cache: Cache) -> LabelingView:
    """The labeling panel; a labeler's has no disagreements (they name other labelers' votes)."""
    with db.read() as conn:
        return dashboard.labeling_view(conn, run_id, cache, votes=caller.role != "labeler")


@router.get("/runs/{run_id}/queries/{query_id}/review", response_model=QueryReview)
def query_review(run_id: RunId, query_id: QueryId, _: OperatorCaller, db: DB) -> Response:
    """One query's segment (with its simulator states) and its labels by labeler: what the labeling
    UI replays when an operator follows a disagreement's "replay in 3D". Operators only."""
    with db.read() as conn:
        return as_json(review.review(conn, run_id, query_id))
