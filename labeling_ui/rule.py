"""What the labeler reads as the run's rule: the task's own words when the run has one (as the
service holds it), else the person's instruction the run was started with, drawn over no regions."""

from __future__ import annotations

from collie.schemas import RunRead
from collie.tasks import Task, task_for_run

INSTRUCTION_MEANING = {
    0: "the robot does what the instruction asks to avoid",
    1: "neither: nothing the instruction speaks of",
    2: "the robot does what the instruction asks for",
}


def run_task(run: RunRead) -> Task | None:
    """The run's stored rule; None without one (an instruction) or when it cannot be read."""
    try:
        return task_for_run(run)
    except ValueError:
        return None


def rule_text(run: RunRead, task: Task | None) -> tuple[str, str, dict[int, str]]:
    """(title, description, one line per class) for the context panel."""
    if task is not None:
        return task.name, task.description, task.meaning
    if run.instruction is not None:
        return "Instruction", run.instruction, INSTRUCTION_MEANING
    return run.task, f"Unknown task '{run.task}' for {run.env}: judge by its name.", {}
