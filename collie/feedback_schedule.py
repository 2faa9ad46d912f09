"""When a run's trainer asks for labels next, from the schedule in the run's config: what the
labeling UI's waiting screen and `collie up`'s progress line tell people."""

from __future__ import annotations

from collie.schemas import RunRead


def next_feedback_epoch(run: RunRead) -> int | None:
    """The first epoch after now at which the trainer asks for labels (trainer/loop.py's
    is_feedback_epoch: from `warmup`, every `feedback_every` epochs, while the budget lasts)."""
    config = run.config
    every, warmup = config.get("feedback_every"), config.get("warmup", 0)
    if not isinstance(every, int) or every <= 0 or not isinstance(warmup, int):
        return None
    if budget_spent(run):
        return None
    after = run.epoch + 1
    upcoming = warmup if after <= warmup else warmup + -(-(after - warmup) // every) * every
    return None if run.epochs_total is not None and upcoming > run.epochs_total else upcoming


def budget_spent(run: RunRead) -> bool:
    """Whether the run has asked its whole label budget `n_total`: no feedback session comes again."""
    q = run.queue  # the budget counts what was asked, retired ones too (the trainer asked them)
    asked = q.pending + q.leased + q.labelled + q.retired
    return run.n_total is not None and max(run.n_labels, asked) >= run.n_total
