"""The in-process oracle teacher as a feedback source: labels each segment at once with the task
rule (bad if any state is bad, good if all are good, else neutral; optional R_error noise)."""

from __future__ import annotations

from typing import Any

from collie.tasks import Task
from collie.teacher import OracleTeacher
from trainer.feedback.base import FeedbackSource, LabelEvent, Segment


class OracleFeedback(FeedbackSource):
    def __init__(self, task: Task, noise_band: float = 0.0, seed: int = 0) -> None:
        self.teacher = OracleTeacher(task, noise_band=noise_band, seed=seed)
        self.n_labelled = 0

    def collect(self, session: int, epoch: int, segments: list[Segment]) -> list[LabelEvent]:
        events = [LabelEvent(s.query_id, self.teacher.label(s.xy, s.pitch)) for s in segments]
        self.n_labelled += len(events)
        return events

    def state_dict(self) -> dict[str, Any]:
        return {"rng": self.teacher.rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state.get("rng") is not None:
            self.teacher.rng.bit_generator.state = state["rng"]
