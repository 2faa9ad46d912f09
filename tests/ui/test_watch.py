"""Watch mode: the dashboard's "watch skills in 3D" link replays every skill of the latest
evaluation from the simulator states the trainer posted, and claims nothing."""

from __future__ import annotations

import time
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest
from playwright.sync_api import Browser

from collie.schemas import RolloutsIn
from trainer.feedback.http_reporter import rollouts_of
from trainer.telemetry import RolloutsReport

from .page import canvas_until, open_labeler, wait_text
from .stack import TOKENS, Stack, rollout_queries

pytestmark = pytest.mark.slow


def evaluation(epoch: int, n: int) -> RolloutsIn:
    """n Ant rollouts as the trainer posts them (through the trainer's own thinning)."""
    walks = rollout_queries("ant", 0, n, seed=21)
    skills, xy, qpos = (np.stack([getattr(w, name) for w in walks]) for name in ("skill", "xy", "qpos"))
    return rollouts_of(RolloutsReport(epoch, skills=skills, xy=xy, stride=2, qpos=qpos))


def test_watch_replays_every_skill_and_claims_nothing(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("ant", 2)  # queries are waiting, but a watcher must not take them
    app = stack.ui(run.id)
    page = open_labeler(browser, f"{app.url}?token={quote(TOKENS['operator'])}&watch={run.id}")
    wait_text(page, "No evaluation to replay yet")
    stack.trainer.post_rollouts(run.id, evaluation(25, 3))  # appears without a reload
    wait_text(page, "skill 1 / 3")
    pixels = canvas_until(page, artifacts / "watch-skill-1.png", lambda p: p.std() > 10.0)
    assert pixels.std() > 10.0
    page.get_by_role("button", name="next ▶").click()
    wait_text(page, "skill 2 / 3")
    assert stack.trainer.run(run.id).queue.leased == 0
    stack.trainer.post_rollouts(run.id, evaluation(50, 4))  # a newer evaluation replaces the skills
    wait_text(page, "evaluation at epoch 50")
    page.context.close()


def test_watching_a_run_the_service_does_not_have_says_so_alone(stack: Stack, browser: Browser) -> None:
    """Was: the labeling screen's waiting words ("Nothing to label right now … The service said: no
    run 99"), its undo button, and one more "Skills" panel at every retry."""
    app = stack.ui()
    page = open_labeler(browser, f"{app.url}?token={quote(TOKENS['operator'])}&watch=99999")
    wait_text(page, "Cannot watch run 99999: no run 99999")
    time.sleep(2 * app.config.wait_s / 10 + 1.0)  # a few of the worker's turns
    body = page.inner_text("body")
    assert "Nothing to label" not in body and "Undo last label" not in body
    assert page.get_by_text("next ▶").count() == 0  # no skill buttons for a run that is not there
    page.context.close()


def test_dashboard_rollouts_leave_the_states_out(stack: Stack) -> None:
    run = stack.post_run("ant", 0)
    stack.trainer.post_rollouts(run.id, evaluation(5, 2))
    full = stack.trainer.rollouts(run.id)[-1].rollouts
    assert len(full) == 2 and all(r.qpos for r in full)  # the watch mode's read
    plain = stack.operator._http.get(f"/runs/{run.id}/rollouts", params={"limit": 1, "states": "false"}).json()
    assert plain[0]["epoch"] == 5 and len(plain[0]["rollouts"]) == 2
    assert all(r["qpos"] is None for r in plain[0]["rollouts"])  # the map's read
    page = stack.operator._http.get(f"/dashboard/runs/{run.id}").json()
    assert page["rollouts"]["epoch"] == 5 and len(page["rollouts"]["rollouts"]) == 2
    assert all(r.get("qpos") is None for r in page["rollouts"]["rollouts"])
