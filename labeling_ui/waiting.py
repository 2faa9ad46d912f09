"""What the page says while nothing is claimable: the epoch now, the epoch of the next feedback
session and when it comes, from the trainer's own schedule (the run's config) and its epoch rate
(the epochs the tab saw go by while it trained, else the timestamps of its metrics). The session
fetches, this words it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from collie.feedback_schedule import budget_spent, next_feedback_epoch
from collie.run_state import run_state
from collie.schemas import FINISHED, MetricsRead, RunRead


@dataclass(frozen=True)
class Forecast:
    epoch: int
    next_feedback: int | None  # None: the trainer's schedule is not in the run's config, or no session is left
    epochs_per_s: float | None  # from the last metrics posted; None before two of them

    @property
    def eta_s(self) -> float | None:
        if self.next_feedback is None or not self.epochs_per_s:
            return None
        return max(0.0, (self.next_feedback - self.epoch) / self.epochs_per_s)


def epoch_rate(metrics: Sequence[MetricsRead]) -> float | None:
    """Epochs per second between the oldest and the newest of `metrics`."""
    if len(metrics) < 2:
        return None
    first, last = min(metrics, key=lambda m: m.epoch), max(metrics, key=lambda m: m.epoch)
    seconds = (last.created_at - first.created_at).total_seconds()
    return (last.epoch - first.epoch) / seconds if seconds > 0 and last.epoch > first.epoch else None


def forecast(run: RunRead, metrics: Sequence[MetricsRead], seen_rate: float | None = None) -> Forecast:
    """`seen_rate`: the rate the tab saw (EpochClock), which wins where there is one: it counts
    training time only, while the metrics' span also holds the waits for labels (several times the
    training time, so an ETA several times too long)."""
    return Forecast(run.epoch, next_feedback_epoch(run), seen_rate or epoch_rate(metrics))


class EpochClock:
    """Epochs per second as this tab sees a run's epoch advance while it trains (a pause or a wait
    for labels starts the look again): the ETA's rate, also before the trainer has posted two
    metrics (a robot's first evaluation may lie a hundred epochs away)."""

    MIN_S = 5.0  # a shorter look says little

    def __init__(self) -> None:
        self._first: dict[int, tuple[float, int]] = {}  # run → (when, epoch) first seen

    def rate(self, run: RunRead, now: float) -> float | None:
        stands = run.control == "pause" or run.status in ("paused", "waiting_for_labels")
        if stands:  # no epochs go by: look again after it
            self._first.pop(run.id, None)
            return None
        when, epoch = self._first.setdefault(run.id, (now, run.epoch))
        if run.epoch < epoch:  # a restarted trainer replays from its checkpoint: look again from here
            self._first[run.id] = (now, run.epoch)
            return None
        seconds = now - when
        return (run.epoch - epoch) / seconds if seconds >= self.MIN_S and run.epoch > epoch else None


def duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def ended_words(run: RunRead) -> str:
    """Why a run takes no label now, in the labeler's words."""
    return f"run {run.id} is {run_state(run)}: it takes no more labels"


def waiting_text(run: RunRead, fc: Forecast, held_here: int) -> str:
    """The waiting screen's status. `held_here`: this tab's own claims (never "elsewhere")."""
    q = run.queue
    others = max(q.leased - held_here, 0)
    lines = [f"Run {run.id} ({run.env}, {run.task}) is *{run_state(run)}* at epoch **{fc.epoch}**."]
    if run.status not in FINISHED and run.control != "stop":
        if run.control == "pause":
            lines.append("The operator paused it: no feedback session comes until it resumes.")
        elif run.status == "waiting_for_labels":  # no epoch goes by until this session is labelled
            later = f" (at epoch **{fc.next_feedback}**)" if fc.next_feedback is not None else ""
            lines.append(f"The trainer waits for this session's last labels; the next session{later} comes after it.")
        elif fc.next_feedback is not None:
            eta = f", in about **{duration(fc.eta_s)}**" if fc.eta_s is not None else " (no epoch rate yet for an ETA)"
            lines.append(f"Next feedback session at epoch **{fc.next_feedback}**{eta}.")
        elif budget_spent(run):  # was "… when its schedule says so": a wait for nothing
            lines.append(
                f"Its label budget is spent ({run.n_total} segments asked): no more segments come; it trains on "
                "to its last epoch."
            )
        else:
            lines.append("The trainer posts the next feedback session when its schedule says so.")
    if q.pending and run.redundancy > 1 and run.status not in FINISHED:  # none of them is this labeler's to label
        lines.append(
            f"{q.pending} segment(s) wait for other labelers: each needs labels from {run.redundancy} different people."
        )
    tail = f"{run.n_labels} labelled"
    if others and run.status not in FINISHED:  # an ended run's leases only wait to run out
        tail = f"{others} being labelled elsewhere (other labelers, or your other tabs), " + tail
    lines.append(tail + ".")
    return "  \n".join(lines)
