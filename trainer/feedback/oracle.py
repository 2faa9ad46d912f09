"""The in-process oracle teacher as a feedback source: labels each segment at once with the task
rule (bad if any state is bad, good if all are good, else neutral; optional R_error noise)."""

from __future__ import annotations

from typing import Any

from collie.tasks import Task
from collie.teacher import OracleTeacher
from trainer.feedback.base import FeedbackSource, LabelEvent, Segment


class OracleFeedback(FeedbackSource):
    def __init__(self, task: Task | None, noise_band: float = 0.0, seed: int = 0) -> None:
        # a run without a rule has no oracle; the loop refuses to ask it (trainer/loop.py)
        self.teacher = OracleTeacher(task, noise_band=noise_band, seed=seed) if task is not None else None
        self.n_labelled = 0

    def collect(self, session: int, epoch: int, segments: list[Segment]) -> list[LabelEvent]:
        if self.teacher is None:
            raise ValueError("this run has no task rule, so no oracle can label it: label through the service (--api)")
        events = [LabelEvent(s.query_id, self.teacher.label(s.xy, s.pitch)) for s in segments]
        self.n_labelled += len(events)
        return events

    def state_dict(self) -> dict[str, Any]:
        return {} if self.teacher is None else {"rng": self.teacher.rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("rng") is not None and self.teacher is not None:
            self.teacher.rng.bit_generator.state = state["rng"]
