"""What the training loop tells live views, as typed messages, and the Reporter that carries them.

Telemetry is not feedback: a FeedbackSource answers for labels, a Reporter only passes news on
(best effort, never blocking training for long, never raising). The default reporter drops
everything; `trainer/feedback/http_reporter.py` posts to the labeling service. numpy only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

# The loop's words; "stopped" (an operator's stop) is a finished run on the service.
LoopStatus = Literal["training", "waiting_for_labels", "paused", "finished", "failed", "stopped", "interrupted"]


@dataclass(frozen=True)
class StatusReport:
    status: LoopStatus
    epoch: int | None = None
    error: str | None = None  # why a run failed
    progress: bool = False  # a routine epoch tick: may be skipped while the service is unwell


@dataclass(frozen=True)
class MetricsReport:
    """One evaluation's numbers (lists are flattened as name[i] on the way out)."""

    epoch: int
    values: Mapping[str, float | int | Sequence[float] | np.ndarray]


@dataclass(frozen=True)
class RolloutsReport:
    """One evaluation's trajectories, every `stride`-th state: skills (N, dz), x-y (N, T, 2),
    simulator states (N, T, nq) for a 3D replay, and w(s) (N, T) where the method has one."""

    epoch: int
    skills: np.ndarray
    xy: np.ndarray
    stride: int = 1  # environment steps between two consecutive points
    qpos: np.ndarray | None = None
    w: np.ndarray | None = None


class Reporter:
    """Where telemetry goes; this base drops it (runs without a service, tests)."""

    def status(self, report: StatusReport) -> None:
        """A status change (or, with report.progress, the current epoch)."""

    def metrics(self, report: MetricsReport) -> None:
        """An evaluation's metrics."""

    def rollouts(self, report: RolloutsReport) -> None:
        """An evaluation's rollouts."""

    def close(self) -> None:
        """Release connections."""
