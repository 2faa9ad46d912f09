"""An operator reviews a disagreement in 3D: the dashboard's disagreement list links each query to
the labeling UI's review mode, which replays that query from its MuJoCo states beside its labels
by labeler and the oracle's, and never labels or claims from that tab."""

from __future__ import annotations

import time
from pathlib import Path
from urllib.parse import quote

import pytest
from playwright.sync_api import Browser, Page

from collie.client import CollieClient

from .page import TIMEOUT_S, VIEWPORT, canvas_until, open_labeler, wait_text
from .stack import TOKENS, Stack

pytestmark = pytest.mark.slow


def frame_shown(page: Page) -> int:
    """The replay's frame number, as the Frame slider on the page says it."""
    return int(page.get_by_role("slider").first.get_attribute("aria-valuenow") or -1)


def test_a_disagreement_replays_in_3d_and_labels_nothing(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 2, seed=5, redundancy=2)
    for name, value in (("rev-ann", 0), ("rev-bo", 1)):  # bad against neutral on the first segment
        with CollieClient(stack.api, stack.new_labeler(name)) as labeler:
            claimed = labeler.claim(run.id)
            assert claimed is not None and claimed.query.query_id == "0-0"
            labeler.submit(run.id, "0-0", value)  # type: ignore[arg-type]
    app = stack.ui(run.id)
    context = browser.new_context(viewport=VIEWPORT)
    context.set_default_timeout(TIMEOUT_S * 1000)
    dashboard = context.new_page()
    dashboard.goto(f"{stack.api}/?token={quote(TOKENS['operator'])}&ui={quote(app.url, safe='')}#run={run.id}")
    link = dashboard.locator('#disagreements-body tr[data-query="0-0"] a.replay-3d')
    link.wait_for()
    with context.expect_page() as opened:
        link.click()
    page = opened.value
    wait_text(page, "Reviewing query")
    wait_text(page, "Counts as")
    text = page.inner_text("body")
    assert "0-0" in text and "rev-ann: bad" in text and "rev-bo: neutral" in text
    assert "Counts as bad" in text and "Oracle (the task rule) " in text  # a tie goes to the safer label
    assert "your labels count" not in text  # an operator's review tab says it labels nothing
    seen = {frame_shown(page)}
    deadline = time.monotonic() + TIMEOUT_S
    while len(seen) < 3 and time.monotonic() < deadline:  # the replay plays by itself
        time.sleep(0.2)
        seen.add(frame_shown(page))
    assert len(seen) >= 3, f"the replay did not advance: frames {sorted(seen)}"
    assert canvas_until(page, artifacts / "review-0-0.png", lambda p: p.std() > 10.0).std() > 10.0
    assert not page.get_by_role("button", name="1 · Bad").is_visible()
    for key in ("1", "3", "x", "u"):
        page.keyboard.press(key)
    wait_text(page, "Review only")
    time.sleep(1.0)  # what a key sent would have reached the service by now
    events = stack.trainer.label_events(run.id)
    assert sorted((e.labeler, e.query_id) for e in events) == [("rev-ann", "0-0"), ("rev-bo", "0-0")]
    assert stack.trainer.run(run.id).queue.leased == 0  # the review claimed nothing
    context.close()


@pytest.mark.parametrize(
    ("query", "said"),
    [("nope", "no query 'nope' in run"), ("bad id!", "is not a query id")],
)
def test_a_review_of_a_query_that_is_not_there_says_so(stack: Stack, browser: Browser, query: str, said: str) -> None:
    run = stack.post_run("point", 1, seed=6)
    app = stack.ui(run.id)
    page = open_labeler(browser, f"{app.url}?token={quote(TOKENS['operator'])}&review={run.id}&query={quote(query)}")
    wait_text(page, "Cannot replay query")
    wait_text(page, said)
    assert stack.trainer.run(run.id).queue.leased == 0
    page.context.close()


def test_a_labeler_token_cannot_review(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 1, seed=7)
    app = stack.ui(run.id)
    page = open_labeler(browser, f"{app.url}?token={quote(stack.new_labeler('rev-cy'))}&review={run.id}&query=0-0")
    wait_text(page, "A review needs an operator token")
    assert stack.trainer.run(run.id).queue.leased == 0
    page.context.close()
