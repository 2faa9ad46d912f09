"""An operator's review of one query in 3D (`?review=RUN&query=ID`, the dashboard's "replay in 3D"
on a disagreement): the segment replays from the simulator states the trainer posted with it, on
loop at the tab's speed, beside its labels by labeler, the label it counts as and the oracle's.
Nothing is claimed or labelled: the state machine refuses every label key in this phase (tab.py).
Runs on the tab's worker; draws through the tab's screen."""

from __future__ import annotations

import numpy as np
from pydantic import TypeAdapter, ValidationError

from collie.dashboard_schemas import QueryReview
from collie.schemas import QueryId, RunRead
from labeling_ui.models import ModelError, Poser, replay_model
from labeling_ui.panels import LABEL_NAMES, skill_text
from labeling_ui.screen import TabScreen
from labeling_ui.service import Rejected, ServiceLink

QUERY_ID: TypeAdapter[str] = TypeAdapter(QueryId)


def _word(value: int | None) -> str:
    return "—" if value is None else f"**{LABEL_NAMES[value]}**"


def verdicts(run: RunRead, review: QueryReview) -> str:
    """Who labelled the query what, what it counts as, and the oracle's label."""
    labels = " · ".join(f"{name}: {_word(v)}" for name, v in review.labels.items()) or "none yet"
    counts = _word(review.effective) if review.effective is not None else f"not yet (needs {run.redundancy} labels)"
    oracle = _word(review.oracle) if review.oracle is not None else "cannot judge this segment"
    if not review.has_rule:
        oracle = "no task rule (instruction only)" if run.instruction is not None else "no readable task rule"
    return f"**Labels** {labels}  \n**Counts as** {counts}  \n**Oracle** (the task rule) {oracle}"


def details(run: RunRead, review: QueryReview) -> str:
    """The context panel's words about the segment."""
    q = review.query
    return (
        f"**Query** `{q.query_id}` · **run** {run.id} · {run.env} · {run.method}  \n"
        f"**epoch** {q.epoch} · **feedback session** {q.session} · **frames** {len(q.qpos)} from step {q.start}  \n"
        f"**skill** {skill_text(q.skill)}"
    )


def show_review(screen: TabScreen, link: ServiceLink, role: str | None, run_id: int, query_id: str) -> None:
    """Replay `query_id` of run `run_id` with its labels, or say clearly why it cannot be."""
    where = f"query `{query_id}` of run {run_id}"
    if role != "operator":
        screen.show_alone(f"⚠️ **A review needs an operator token**: this tab is signed in as a {role}.")
        return
    try:
        QUERY_ID.validate_python(query_id)
    except ValidationError:
        screen.show_alone(f"⚠️ **Cannot replay {where}**: `{query_id}` is not a query id.")
        return
    try:
        run = link.run(run_id)
        review = link.review(run_id, query_id)
    except Rejected as exc:  # an unknown run or query: the service names it
        screen.show_alone(f"⚠️ **Cannot replay {where}**: {exc}.")
        return
    if not review.query.qpos:
        screen.show_alone(f"⚠️ **Cannot replay {where}**: the trainer posted no simulator states with it.")
        return
    try:
        poser = Poser(replay_model(run.env), np.asarray(review.query.qpos, float))
    except ModelError as exc:
        screen.show_alone(f"⚠️ **Cannot replay {where}**: {exc}")
        return
    status = f"**Reviewing query `{query_id}`** of run {run_id}: a replay only, this tab sends no label.  \n"
    screen.show_review(run, poser, review, status + verdicts(run, review), details(run, review))
