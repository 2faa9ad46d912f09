"""The dashboard's API against a live service: the rollout and metrics endpoints and their bounds,
the thinned metric history, the labeling panel (with the oracle's agreement), the runs long poll,
and the page itself being served at /."""

from __future__ import annotations

import threading
import time
from typing import Any

import httpx
import numpy as np
import pytest
from service.conftest import DIMS, TOKENS, make_run_spec

from backend.server import BackgroundServer
from backend.services import label_stats, telemetry
from collie.client import ApiError, CollieClient
from collie.dashboard_schemas import MAX_HISTORY_POINTS, MAX_LABELLED_POINTS
from collie.schemas import MAX_ROLLOUT_POINTS, MAX_ROLLOUTS, MetricsIn, QueryIn, Rollout, RolloutsIn, SessionPost
from trainer.feedback.http_reporter import rollouts_of
from trainer.telemetry import RolloutsReport

OPERATOR = {"Authorization": f"Bearer {TOKENS['operator']}"}


def get(live: BackgroundServer, path: str, headers: dict[str, str] | None = None, **params: Any) -> httpx.Response:
    return httpx.get(
        f"{live.url}/api/{path}", headers=OPERATOR if headers is None else headers, params=params, timeout=30
    )


def north_query(query_id: str, y: float) -> QueryIn:
    """A segment on the line x = 0.5 at height y: inside the north wedge (oracle: neutral) for y ≥ 0.5."""
    h = DIMS.horizon
    return QueryIn(
        query_id=query_id,
        start=0,
        skill=[1.0, 0.0],
        obs=[[0.0] * DIMS.obs_dim] * h,
        xy=[[0.5, y + 0.01 * i] for i in range(h)],
        pitch=None,
        qpos=[[0.0] * DIMS.nq] * h,
        qvel=[[0.0] * DIMS.nv] * h,
    )


def test_rollout_posts_are_bounded(live: BackgroundServer, trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec())
    point = {"skill": [1.0, 0.0], "xy": [[0.0, 0.0]]}
    for body in (
        {"epoch": 1, "rollouts": [point] * (MAX_ROLLOUTS + 1)},
        {"epoch": 1, "rollouts": [{**point, "xy": [[0.0, 0.0]] * (MAX_ROLLOUT_POINTS + 1)}]},
        {"epoch": 1, "rollouts": [{**point, "extra": {"w": [1.0] * 5000}}]},  # extra over 16 KiB
    ):
        with pytest.raises(ApiError) as refused:
            trainer._send("POST", f"/runs/{run.id}/rollouts", json=body)
        assert refused.value.status == 422
    with pytest.raises(ApiError) as refused:
        too_many = {f"k{i}": 1.0 for i in range(257)}
        trainer._send("POST", f"/runs/{run.id}/metrics", json={"epoch": 1, "values": too_many})
    assert refused.value.status == 422
    assert get(live, f"runs/{run.id}/rollouts", limit=51).status_code == 422
    assert get(live, f"runs/{run.id}/metrics", limit=10_001).status_code == 422


def test_trainer_rollouts_are_thinned_with_w_at_the_same_points() -> None:
    xy = np.cumsum(np.ones((70, 3000, 2)), axis=1)
    xy[0, 5] = np.nan  # dropped, and its w with it
    w = np.broadcast_to(np.arange(3000) / 1500.0, (70, 3000))
    body = rollouts_of(RolloutsReport(3, skills=np.eye(70, 2), xy=xy, stride=2, w=w))
    assert len(body.rollouts) == MAX_ROLLOUTS and all(len(r.xy) == 1000 for r in body.rollouts)
    assert body.rollouts[1].stride == 6  # 2 steps a point, thinned a further 3000 → 1000
    first = body.rollouts[0]
    assert len(first.extra["w"]) == 1000
    steps = [round(p[0]) - 1 for p in first.xy]  # x = step + 1 on these paths
    assert 5 not in steps and first.extra["w"] == [round(s / 1500.0, 2) for s in steps]
    assert len(RolloutsIn.model_validate_json(body.model_dump_json()).model_dump_json()) < 16 * 1024 * 1024
    short = rollouts_of(RolloutsReport(3, skills=np.eye(1, 2), xy=np.array([[[0, 0], [1, 1]]]), stride=2)).rollouts[0]
    assert "w" not in short.extra and short.stride == 2


def test_trainer_rollouts_carry_states_at_the_same_points_for_the_watch_mode() -> None:
    xy = np.cumsum(np.ones((2, 3000, 2)), axis=1)
    qpos = np.concatenate([xy, np.zeros((2, 3000, 13))], axis=2)  # ant-sized states, x and y first
    body = rollouts_of(RolloutsReport(3, skills=np.eye(2), xy=xy, qpos=qpos))
    first = body.rollouts[0]
    assert len(first.qpos) == len(first.xy) == 1000 and len(first.qpos[0]) == 15
    assert [q[:2] for q in first.qpos] == first.xy
    too_wide = RolloutsReport(3, skills=np.eye(1), xy=xy[:1], qpos=np.zeros((1, 3000, 200)))
    assert rollouts_of(too_wide).rollouts[0].qpos is None  # left out, the paths still go
    with pytest.raises(ValueError, match="one state per point"):
        RolloutsIn(epoch=1, rollouts=[{"skill": [1.0], "xy": [[0.0, 0.0]], "qpos": [[0.0], [1.0]]}])
    with pytest.raises(ValueError, match="one per point"):
        RolloutsIn(epoch=1, rollouts=[{"skill": [1.0], "xy": [[0.0, 0.0]], "pitch": [0.1, 0.2]}])


def test_metric_history_is_thinned_and_keeps_the_newest(live: BackgroundServer, trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec())
    with live.app.state.db.write() as conn:  # 2500 evaluations without 2500 round trips
        for epoch in range(2500):
            telemetry.post_metrics(conn, run.id, MetricsIn(epoch=epoch, values={"safe_ratio": epoch / 2500}))
    history = get(live, f"dashboard/runs/{run.id}/metrics", max_points=100).json()
    assert history["n_stored"] == 2500 and len(history["epochs"]) <= 100
    assert history["epochs"][0] == 0 and history["epochs"][-1] == 2499
    assert history["epochs"] == sorted(history["epochs"])
    assert len(history["series"]["safe_ratio"]) == len(history["epochs"])
    small = get(live, f"dashboard/runs/{run.id}/metrics", max_points=2).json()
    assert small["epochs"] == [0, 2499]
    for bad in (1, MAX_HISTORY_POINTS + 1):
        assert get(live, f"dashboard/runs/{run.id}/metrics", max_points=bad).status_code == 422
    page = get(live, f"dashboard/runs/{run.id}")
    assert len(page.json()["metrics"]["epochs"]) <= 1000 and len(page.content) < 200_000


def test_run_page_is_one_consistent_snapshot(live: BackgroundServer, trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec(task="range_north"))
    trainer.set_status(run.id, "training", epoch=4)
    trainer.post_metrics(run.id, MetricsIn(epoch=4, values={"safe_coverage": 3.0}))
    for epoch in (2, 4):
        body = RolloutsIn(epoch=epoch, rollouts=[Rollout(skill=[1.0, 0.0], xy=[[0, 0], [1, 2]])])
        trainer.post_rollouts(run.id, body)
    page = get(live, f"dashboard/runs/{run.id}").json()
    assert page["rollouts"]["epoch"] == 4 and page["metrics"]["series"]["safe_coverage"] == [3.0]
    assert [r["kind"] for r in page["task"]["regions"]] == ["wedge_north", "outside_disc"]
    assert page["last_event_id"] == trainer.run(run.id).last_event_id
    assert page["labels"] == [
        {"value": 0, "name": "bad"},
        {"value": 1, "name": "neutral"},
        {"value": 2, "name": "good"},
    ]
    assert trainer.events(run.id, after=page["last_event_id"]).events == []
    assert get(live, "dashboard/runs/987654").status_code == 404


def test_labeling_panel_counts_pace_and_oracle_agreement(
    live: BackgroundServer, trainer: CollieClient, labeler: CollieClient, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = trainer.create_run(make_run_spec(task="north"))
    ys = [1.0, 1.0, -3.0, -3.0, 2.0]  # north: above the line y = |x| is neutral, below it bad
    queries = [north_query(f"q{i}", y) for i, y in enumerate(ys)]
    trainer.post_session(run.id, SessionPost(session=0, epoch=2, queries=queries))
    answers = {"q0": (1, 2.0), "q1": (0, 4.0), "q2": (0, 6.0), "q3": ("skip", None), "q4": (1, 8.0)}
    for _ in range(len(answers)):
        claim = labeler.claim(run.id)
        assert claim is not None
        value, seconds = answers[claim.query.query_id]
        labeler.submit(run.id, claim.query.query_id, value, seconds=seconds)
    monkeypatch.setattr(label_stats, "MAX_LABELLED_SEGMENTS", 3)
    view = get(live, f"dashboard/runs/{run.id}/labeling").json()
    stats = view["labeling"]
    assert stats["n_labels"] == 4 and stats["queue"]["labelled"] == 4 and stats["queue"]["pending"] == 1
    assert stats["judged"] == 4 and stats["agreement"] == 0.75  # q1 was labelled bad in the wedge
    assert stats["labels_per_min"] == pytest.approx(4 / 5)
    [me] = stats["labelers"]
    assert (me["name"], me["labels"], me["skips"], me["median_s"], me["agreement"]) == ("labeler", 4, 1, 5.0, 0.75)
    assert view["n_labelled"] == 4 and len(view["labelled"]) == 3
    assert sum(len(s["xy"]) for s in view["labelled"]) <= MAX_LABELLED_POINTS
    shown = {s["query_id"]: (s["label"], s["oracle"]) for s in view["labelled"]}
    assert shown == {"q4": (1, 1), "q2": (0, 0), "q1": (0, 1)}  # the newest labels


def test_runs_list_is_a_long_poll(live: BackgroundServer, trainer: CollieClient, labeler: CollieClient) -> None:
    run = trainer.create_run(make_run_spec())
    trainer.post_metrics(run.id, MetricsIn(epoch=12, values={"safe_ratio": 0.5}))
    first = get(live, "dashboard/runs").json()
    mine = next(r for r in first["runs"] if r["id"] == run.id)
    assert (mine["epoch"], mine["preset"], mine["status"], mine["last_label_at"]) == (12, "smoke", "training", None)
    assert "config" not in mine

    started = time.monotonic()
    quiet = get(live, "dashboard/runs", after=first["version"], wait_s=0.5).json()
    assert quiet["version"] == first["version"] and time.monotonic() - started >= 0.45

    answer: dict[str, Any] = {}

    def wait() -> None:
        answer["page"] = get(live, "dashboard/runs", after=first["version"], wait_s=20).json()
        answer["at"] = time.monotonic()

    waiter = threading.Thread(target=wait)
    waiter.start()
    time.sleep(0.3)
    posted = time.monotonic()
    trainer.set_status(run.id, "paused", epoch=13)
    waiter.join(25)
    assert answer["page"]["version"] > first["version"] and answer["at"] - posted < 10
    assert next(r for r in answer["page"]["runs"] if r["id"] == run.id)["status"] == "paused"


def test_reading_needs_a_token_and_any_role_may_read(live: BackgroundServer, trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec())
    for path in (
        "dashboard/runs",
        f"dashboard/runs/{run.id}",
        f"dashboard/runs/{run.id}/metrics",
        f"dashboard/runs/{run.id}/labeling",
    ):
        assert get(live, path, headers={}).status_code == 401
        assert get(live, path, headers={"Authorization": "Bearer not-a-token"}).status_code == 401
        for role in ("operator", "trainer", "labeler"):
            assert get(live, path, headers={"Authorization": f"Bearer {TOKENS[role]}"}).status_code == 200


def test_the_page_is_served_at_the_root(live: BackgroundServer) -> None:
    index = httpx.get(f"{live.url}/")
    assert index.status_code == 200 and "text/html" in index.headers["content-type"]
    assert 'src="vendor/plotly-basic.min.js"' in index.text and 'src="js/main.js" type="module"' in index.text
    module = httpx.get(f"{live.url}/js/main.js")
    assert module.status_code == 200 and "javascript" in module.headers["content-type"]  # ES modules need it
    plotly = httpx.get(f"{live.url}/vendor/plotly-basic.min.js")
    assert plotly.status_code == 200 and b"window.Plotly" in plotly.content
    assert httpx.get(f"{live.url}/api/health").json()["status"] == "ok"  # the API is not shadowed by /
    assert httpx.head(f"{live.url}/").status_code == 200
    token = {"Authorization": f"Bearer {TOKENS['operator']}"}
    head = httpx.head(f"{live.url}/api/me", headers=token)  # was 404: the page's mount took it
    assert head.status_code == 405 and head.headers["allow"] == "GET"
    missing = httpx.get(f"{live.url}/api/no-such-route", headers=token)
    assert missing.status_code == 404 and missing.json() == {"detail": "Not Found"}


def test_labelled_paths_keep_huge_coordinates() -> None:
    """A robot flung far away (diverged physics) still posts finite x-y; the panel's rounding to
    thousandths must not turn 1e306 into inf, which JSON writes as null."""
    xy = np.array([[1.23456, -2.0], [1e306, -1e306], [3e15, 0.0006]])
    assert label_stats.thinned(xy, 10) == [[1.235, -2.0], [1e306, -1e306], [3e15, 0.001]]
