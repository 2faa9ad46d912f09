"""The feedback-source interface: Algorithm 1, lines 5–7 ("query labelers for feedback").

The loop hands a feedback session's segments to a source and blocks in `collect` until the
source's policy says the session is done. Sources that allow revisions (a labeler's undo) report
them later through `revisions`; the loop applies them to D0/D1/D2 before the next update.
"""

from __future__ import annotations

import abc
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from collie.labels import Label


class StopRequested(Exception):
    """Raised by a source when an operator stops the run while the trainer waits."""


TOKEN_ADVICE = (
    "resume it with --resume and an operator's token (a trainer token acts only on the runs its own principal created)"
)


class SourceRefused(Exception):
    """Raised by a source whose service refuses the trainer (a revoked or wrong token, a session past
    the run's budget): no label can come, so the run ends resumable, checkpointed, as after a signal.
    `advice`: what the user can do, said after the message."""

    def __init__(self, message: str, advice: str = TOKEN_ADVICE) -> None:
        super().__init__(message)
        self.advice = advice


@dataclass
class Segment:
    """One query: H consecutive states of one training trajectory (σ = (s_t, …, s_{t+H−1}))."""

    query_id: str  # unique within the run, chosen by the trainer: "<session>-<index>"
    session: int  # feedback session index, 0-based
    epoch: int  # epoch at which the session was opened
    skill: np.ndarray  # (dim_z,)
    start: int  # index of s_t within its trajectory
    obs: np.ndarray  # (H, *obs_shape) raw observations, uint8 images for pixel envs (the labelled sets use these)
    xy: np.ndarray  # (H, 2) x-y (y = 0 for 1-D envs)
    pitch: np.ndarray  # (H,) pitch in radians (nan where undefined)
    qpos: np.ndarray  # (H, nq) for replay
    qvel: np.ndarray  # (H, nv)
    score: float = 0.0  # selection score I(σ) (0 for uniform picks)
    path_xy: np.ndarray | None = None  # (T+1, 2) the whole trajectory's x-y, for context in UIs
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True)
class LabelEvent:
    """An effective label for one query; label None means "withdrawn" (e.g. undone, no relabel yet)."""

    query_id: str
    label: Label | None


class FeedbackSource(abc.ABC):
    """What the training loop needs from anything that can label segments."""

    @abc.abstractmethod
    def collect(self, session: int, epoch: int, segments: list[Segment]) -> list[LabelEvent]:
        """Publish a session's segments and block until its labels are in (or the source's
        timeout policy ends the wait). Returns the effective labels that arrived."""

    interrupted: str | None = None  # set by interrupt()
    refusal: SourceRefused | None = None  # the service refused the trainer between epochs (raised at control())

    def interrupt(self, reason: str) -> None:
        """Ask a blocking `collect` to raise StopRequested(reason) at its next look (within one wait
        chunk): the trainer's signal handler calls it, as a backstop to the exception it raises,
        which Python drops if it lands in a weakref callback or __del__."""
        self.interrupted = reason

    def revisions(self) -> list[LabelEvent]:
        """Labels changed since the last call (undo, relabel, late arrivals). Non-blocking."""
        return []

    def control(self, epoch: int | None = None) -> Literal["run", "pause", "stop"]:
        """Operator's wish for the run, polled once per epoch (`epoch`: the trainer's, for a status it shows)."""
        return "run"

    def state_dict(self) -> dict[str, Any]:
        """What a checkpoint must keep for this source to resume as it was (e.g. a teacher's RNG)."""
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:  # noqa: B027
        """Restore what state_dict returned."""

    def history(self, held: Collection[str] = ()) -> list[tuple[Segment, int]] | None:
        """All labelled segments known to the source (used to rebuild D0/D1/D2 after a restart).
        None when the source keeps no history (then the trainer's checkpoint is authoritative).
        `held`: the query ids whose segments the trainer already holds (its checkpoint's), labelled
        or not: a label one of them gets later is a revision for the trainer, as before the restart."""
        return None

    def close(self) -> None:  # noqa: B027
        """Release connections."""
