"""A run's state in people's words, as the labeling UI and `collie up`'s progress line say it."""

from __future__ import annotations

from collie.schemas import FINISHED, RunRead


def run_state(run: RunRead) -> str:
    """The run's state in words: a run that was stopped says *stopped*, not finished (the trainer
    reports a stop as status "finished")."""
    if run.control == "stop" and run.status not in FINISHED:
        return "stopping"
    if run.status == "finished" and run.control == "stop":
        return "stopped"
    return run.status.replace("_", " ")
