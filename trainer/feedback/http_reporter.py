"""Telemetry to the labeling service: status, metrics and rollouts, from the loop's typed reports
to the wire schemas. Best effort by contract: a failed post is logged, bulky reports are skipped
for a while after a failure, and nothing raises into the training loop. The one exception is the
run's final status (finished, failed): lost, the service would show the run training for ever, so a
refusal the service may lift is retried for up to a minute. numpy only, HTTP only."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from collie.client import Backoff, CollieClient, Unavailable
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
FINAL: tuple[RunStatus, ...] = ("finished", "failed")  # a stopped run is reported finished (run_status)
FINAL_RETRY_S = 60.0  # how long a trainer's exit may wait for the service to take its final status


class HttpReporter(Reporter):
    """Posts run `run_id`'s telemetry with a trainer token; `shown` is the last status it delivered."""

    def __init__(
        self,
        api: str,
        token: str,
        run_id: int,
        timeout_s: float = 5.0,
        final_retry_s: float = FINAL_RETRY_S,
        backoff: Backoff | None = None,
    ) -> None:
        self.run_id = run_id
        self.client = CollieClient(api, token, timeout_s=timeout_s, part="trainer")
        self.shown: RunStatus | None = None
        self.final_retry_s = final_retry_s
        self.backoff = backoff or Backoff()  # the clients' one retry policy: 0.1 s doubling to 5 s
        self._quiet_until = 0.0

    def status(self, report: StatusReport) -> None:
        status, message = run_status(report)
        post = lambda: self.client.set_status(self.run_id, status, report.epoch, message)  # noqa: E731
        if status in FINAL:
            delivered = self._deliver_final(status, report.epoch, post)
        else:
            delivered = self._deliver("status", report.progress, post)
        if delivered:
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
            why = " (the service is busy or unreachable; best effort)" if isinstance(exc, Unavailable) else ""
            log.warning("report %s not delivered%s: %s", what, why, exc)
            self._quiet_until = time.monotonic() + QUIET_AFTER_FAILURE_S  # status changes (rare) are still tried
            return False

    def _deliver_final(self, status: RunStatus, epoch: int | None, post: Callable[[], Any]) -> bool:
        """`post` until it is taken; a refusal the service may lift (Unavailable: a 5xx such as a
        database it cannot write, 429, no answer) is retried with the shared backoff for up to
        `final_retry_s`, so the trainer never hangs at its exit; any other (401, 409) is final."""
        what = f"run {self.run_id}'s final status ({status} at epoch {epoch})"
        deadline = time.monotonic() + self.final_retry_s
        delays = self.backoff.delays()
        failed = False
        while True:
            try:
                post()
            except Unavailable as exc:
                left = deadline - time.monotonic()
                if left <= 0:
                    shown = self.shown or "as it last heard"
                    log.warning(
                        "%s not delivered in %.0f s (%s); the service shows the run %s",
                        what,
                        self.final_retry_s,
                        exc,
                        shown,
                    )
                    return False
                if not failed:  # one line now, one at the end: the trainer's exit waits on this
                    log.warning("%s not delivered yet (%s); retrying for up to %.0f s", what, exc, self.final_retry_s)
                    failed = True
                time.sleep(min(next(delays), left))
                continue
            except Exception as exc:  # refused for good (401, 409): retrying cannot help
                log.warning("report status not delivered: %s", exc)
                return False
            if failed:  # the line above said it was not: say it was, in the end
                log.warning("%s delivered", what)
            return True


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
