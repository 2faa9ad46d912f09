"""Telemetry to the labeling service: status, metrics and rollouts, from the loop's typed reports
to the wire schemas. Best effort by contract: a failed post is logged, bulky reports are skipped
for a while after a failure, and nothing raises into the training loop. numpy only, HTTP only."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from collie.client import CollieClient
from collie.schemas import (
    MAX_METRICS,
    MAX_QPOS_WIDTH,
    MAX_ROLLOUT_POINTS,
    MAX_ROLLOUTS,
    MetricsIn,
    Rollout,
    RolloutsIn,
    RunStatus,
)
from trainer.telemetry import MetricsReport, Reporter, RolloutsReport, StatusReport

log = logging.getLogger(__name__)
QUIET_AFTER_FAILURE_S = 10.0


class HttpReporter(Reporter):
    """Posts run `run_id`'s telemetry with a trainer token; `shown` is the last status it delivered."""

    def __init__(self, api: str, token: str, run_id: int, timeout_s: float = 5.0) -> None:
        self.run_id = run_id
        self.client = CollieClient(api, token, timeout_s=timeout_s, part="trainer")
        self.shown: RunStatus | None = None
        self._quiet_until = 0.0

    def status(self, report: StatusReport) -> None:
        status, message = run_status(report)
        post = lambda: self.client.set_status(self.run_id, status, report.epoch, message)  # noqa: E731
        if self._deliver("status", report.progress, post):
            self.shown = status

    def metrics(self, report: MetricsReport) -> None:
        body = MetricsIn(epoch=max(report.epoch, 0), values=flat_numbers(report.values))
        self._deliver("metrics", True, lambda: self.client.post_metrics(self.run_id, body))

    def rollouts(self, report: RolloutsReport) -> None:
        self._deliver("rollouts", True, lambda: self.client.post_rollouts(self.run_id, rollouts_of(report)))

    def close(self) -> None:
        self.client.close()

    def _deliver(self, what: str, skippable: bool, post: Callable[[], Any]) -> bool:
        if skippable and time.monotonic() < self._quiet_until:
            return False  # the service failed recently: skip the bulky reports, do not slow training down
        try:
            post()
            return True
        except Exception as exc:  # best effort by contract: a dashboard never stops training
            log.warning("report %s not delivered: %s", what, exc)
            self._quiet_until = time.monotonic() + QUIET_AFTER_FAILURE_S  # status changes (rare) are still tried
            return False


def run_status(report: StatusReport) -> tuple[RunStatus, str | None]:
    """The loop's words → the service's: "stopped" is a finished run with a message."""
    if report.status == "stopped":
        return "finished", "stopped by an operator"
    if report.status == "interrupted":  # the loop does not send it (the run goes on after --resume)
        return "paused", "the trainer process was told to end; --resume continues the run"
    return report.status, (report.error[:1000] if report.error else None)


def flat_numbers(record: Mapping[str, Any]) -> dict[str, float]:
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


def rollouts_of(report: RolloutsReport, max_points: int = 1000) -> RolloutsIn:
    """At most MAX_ROLLOUTS paths of at most max_points finite points each (evenly thinned, each
    rollout's stride says how many env steps lie between its points; millimetres are plenty for a
    plot); w(s) at the same points goes in each rollout's extra["w"], the simulator state at the
    same points in its qpos (for a 3D replay)."""
    skills = np.asarray(report.skills, dtype=float)
    weights: Any = [] if report.w is None else report.w
    states: Any = [] if report.qpos is None else report.qpos
    limit = min(max_points, MAX_ROLLOUT_POINTS)
    rollouts = []
    for i, path in enumerate(list(report.xy)[:MAX_ROLLOUTS]):
        xy = np.asarray(path, dtype=float).reshape(-1, 2)
        kept = np.flatnonzero(np.isfinite(xy).all(axis=1))
        stride = report.stride
        if len(kept) > limit:
            stride = max(1, round(report.stride * (len(kept) - 1) / (limit - 1)))
            kept = kept[np.linspace(0, len(kept) - 1, limit).round().astype(int)]
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
            Rollout(
                skill=np.nan_to_num(skill).tolist(),
                xy=np.round(xy[kept], 3).tolist(),
                qpos=qpos,
                stride=stride,
                extra=extra,
            )
        )
    return RolloutsIn(epoch=max(report.epoch, 0), rollouts=rollouts)
