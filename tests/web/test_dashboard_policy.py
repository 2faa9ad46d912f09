"""The dashboard's feedback timeout control in Debian's Chromium against a live service: it shows
the run's policy, sets and clears it (the service's run changes), follows a change made elsewhere
from the stream, and shows a refusal."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from service.conftest import TOKENS, make_run_spec

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MAX_FEEDBACK_TIMEOUT_S, RunRead

WAIT_MS = 30_000


@pytest.fixture(scope="module")
def run(trainer: CollieClient) -> RunRead:
    return trainer.create_run(make_run_spec().model_copy(update={"feedback_timeout_s": 120.0}))


@pytest.fixture(scope="module")
def page(live: BackgroundServer, browser: Any, run: RunRead) -> Iterator[Any]:
    # bypass_csp: Playwright's wait_for_function evaluates strings, which the dashboard's policy
    # forbids (tests/service/test_security_headers.py checks the page works under it)
    page = browser.new_page(bypass_csp=True, viewport={"width": 1400, "height": 1000})
    page.set_default_timeout(WAIT_MS)
    page.goto(f"{live.url}/?token={TOKENS['operator']}#run={run.id}")
    yield page
    page.close()


def shown(page: Any, text: str) -> None:
    page.wait_for_function(f"document.querySelector('#policy-text').textContent === {text!r}")


def test_the_control_sets_and_clears_the_policy(page: Any, trainer: CollieClient, run: RunRead) -> None:
    shown(page, "continue after 120 s")  # what the trainer stored at creation
    assert page.is_enabled("#policy-apply") and page.is_enabled("#policy-wait")
    page.fill("#policy-seconds", "30")
    page.click("#policy-apply")
    shown(page, "continue after 30 s")
    assert trainer.run(run.id).feedback_timeout_s == 30.0
    page.wait_for_function(
        "document.querySelector('#policy-seconds').value === ''"
    )  # cleared by the answer, maybe after the stream's news
    page.click("#policy-wait")
    shown(page, "wait for every label")
    assert trainer.run(run.id).feedback_timeout_s is None
    assert not page.is_enabled("#policy-wait")  # already so
    kinds = [(e.kind, e.data.model_dump()) for e in trainer.events(run.id).events if e.kind == "policy"]
    assert kinds == [("policy", {"timeout_s": 30.0}), ("policy", {"timeout_s": None})]


def test_a_change_made_elsewhere_shows_live(page: Any, live: BackgroundServer, run: RunRead) -> None:
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.set_feedback_policy(run.id, 2.5)
    shown(page, "continue after 2.5 s")  # from the run's stream, no reload
    assert page.get_attribute("#policy", "data-timeout") == "2.5"


def test_a_bad_value_is_refused_and_said(page: Any, trainer: CollieClient, run: RunRead) -> None:
    for nothing in ("-3", "0"):  # said at once, without asking the service
        page.fill("#policy-seconds", nothing)
        page.click("#policy-apply")
        page.wait_for_function("document.querySelector('#control-message').textContent.includes('more than 0')")
        page.evaluate("document.querySelector('#control-message').textContent = ''")
    sent: list[str] = []
    page.on("request", lambda r: sent.append(r.url) if r.url.endswith("/feedback-policy") else None)
    refusals = (
        ("1,5", '"1,5" is not a number of seconds (for 1.5 s, write it with a point)'),
        ("1,500", '"1,500" is not a number of seconds'),  # no guess: 1.5 or 1500
        ("abc", '"abc" is not a number of seconds'),
        ("1e400", '"1e400" is more seconds than a number holds: enter fewer'),  # Infinity: JSON sends null, "wait"
    )
    for text, said in refusals:
        page.fill("#policy-seconds", text)  # was: a number field read "1,5" as 15, and applied it
        page.click("#policy-apply")
        page.wait_for_function(f"document.querySelector('#control-message').textContent === {said!r}")
        page.evaluate("document.querySelector('#control-message').textContent = ''")
    for too_long in ("1e9", str(MAX_FEEDBACK_TIMEOUT_S + 0.5)):  # past the service's week: said, not sent
        page.fill("#policy-seconds", too_long)
        page.click("#policy-apply")
        page.wait_for_function(
            "document.querySelector('#control-message').textContent"
            f'.startsWith("a session\'s labels can be waited for at most {MAX_FEEDBACK_TIMEOUT_S} s (7 days)")'
        )
        page.evaluate("document.querySelector('#control-message').textContent = ''")
    assert sent == []  # the service's validator text never reaches the page
    assert trainer.run(run.id).feedback_timeout_s == 2.5
    shown(page, "continue after 2.5 s")


def test_a_timeout_set_while_the_trainer_waits_says_it_may_release_the_session(
    page: Any, trainer: CollieClient, run: RunRead
) -> None:
    """The trainer times its waiting session from its start: a shorter timeout lets it go at once."""
    trainer.set_status(run.id, "waiting_for_labels")
    page.wait_for_function("document.body.dataset.runStatus === 'waiting_for_labels'")
    page.fill("#policy-seconds", "2.5")
    page.click("#policy-apply")
    page.wait_for_function(
        "document.querySelector('#control-message').textContent"
        ".startsWith('the trainer was waiting for labels: if its session has waited 2.5 s already')"
    )
    trainer.set_status(run.id, "training")
    page.wait_for_function("document.body.dataset.runStatus === 'training'")


def test_a_labeler_token_may_not_set_it(
    live: BackgroundServer, browser: Any, trainer: CollieClient, run: RunRead
) -> None:
    labeler = browser.new_page(bypass_csp=True)
    labeler.set_default_timeout(WAIT_MS)
    labeler.goto(f"{live.url}/?token={TOKENS['labeler']}#run={run.id}")
    labeler.wait_for_function("document.body.dataset.role === 'labeler'")
    assert not labeler.is_visible("#policy")  # not offered (was: it answered 403 once applied)
    labeler.close()
    refused = httpx.post(
        f"{live.url}/api/runs/{run.id}/feedback-policy",
        json={"timeout_s": 9},
        headers={"Authorization": f"Bearer {TOKENS['labeler']}"},
    )
    assert refused.status_code == 403
    assert trainer.run(run.id).feedback_timeout_s == 2.5


def test_a_stopped_run_disables_the_control(page: Any, live: BackgroundServer, run: RunRead) -> None:
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.stop(run.id)
    page.wait_for_function("document.body.dataset.runControl === 'stop'")
    assert not page.is_enabled("#policy-apply") and not page.is_enabled("#policy-wait")


def test_watch_link_opens_the_labeling_ui_in_watch_mode(live: BackgroundServer, browser: Any, run: RunRead) -> None:
    page = browser.new_page(bypass_csp=True)
    page.goto(f"{live.url}/?token={TOKENS['operator']}&ui=http%3A%2F%2F127.0.0.1%3A8080%2F#run={run.id}")
    page.wait_for_selector("#watch-3d:not([hidden])", timeout=WAIT_MS)
    href = page.get_attribute("#watch-3d", "href")
    assert href == f"http://127.0.0.1:8080/?watch={run.id}&token={TOKENS['operator']}"
    page.close()
