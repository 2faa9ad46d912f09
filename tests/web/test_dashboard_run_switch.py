"""What the dashboard shows for one run stays that run's, in Debian's Chromium against a live
service: an armed Stop and a control's words do not carry to the next run opened, another
operator's quality settings hold, a closed run offers no instructions, a run's trainer gone silent
is said in its own header, runs open from the keyboard, and the tab's title names the run."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
from service.conftest import TOKENS, make_run_spec

from backend.models import Run
from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import RunRead

WAIT_MS = 30_000


@pytest.fixture(scope="module")
def runs(trainer: CollieClient) -> list[RunRead]:
    return [trainer.create_run(make_run_spec()) for _ in range(2)]


@pytest.fixture
def page(live: BackgroundServer, browser: Any, runs: list[RunRead]) -> Iterator[Any]:
    page = browser.new_page(bypass_csp=True, viewport={"width": 1400, "height": 1000})
    page.set_default_timeout(WAIT_MS)
    page.goto(f"{live.url}/?token={TOKENS['operator']}#run={runs[0].id}")
    page.wait_for_function(f"document.querySelector('#run-title').textContent.startsWith('Run #{runs[0].id} ')")
    yield page
    page.close()


def open_run(page: Any, run_id: int) -> None:
    page.click(f'#runs-body tr[data-run-id="{run_id}"]')
    page.wait_for_function(f"document.querySelector('#run-title').textContent.startsWith('Run #{run_id} ')")


def test_a_stop_armed_on_one_run_is_disarmed_by_opening_another(
    page: Any, runs: list[RunRead], trainer: CollieClient
) -> None:
    """Was: "Really stop?" carried over, and one click stopped the run opened since."""
    page.click("#stop")
    assert page.text_content("#stop") == "Really stop?"
    open_run(page, runs[1].id)
    assert page.text_content("#stop") == "Stop"
    page.click("#stop")  # arms it for this run, stops nothing
    assert page.text_content("#stop") == "Really stop?"
    assert [trainer.run(r.id).control for r in runs] == ["run", "run"]


def test_a_controls_words_are_its_runs_and_no_answer_is_no_refusal(
    page: Any, live: BackgroundServer, runs: list[RunRead]
) -> None:
    page.fill("#policy-seconds", "abc")
    page.click("#policy-apply")
    page.wait_for_function("document.querySelector('#control-message').textContent.includes('not a number')")
    open_run(page, runs[1].id)
    assert page.text_content("#control-message") == ""  # was: run 1's words under run 2
    page.route("**/pause", lambda route: route.abort())  # the service does not answer
    page.click("#pause")
    page.wait_for_function("document.querySelector('#control-message').textContent !== ''")
    said = page.text_content("#control-message")
    assert said.startswith("pause not done: no answer from the service (") and "refused" not in said
    page.unroute("**/pause")
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.set_feedback_policy(runs[1].id, 60.0)  # news on the stream: the service answers again
    page.wait_for_function("document.querySelector('#control-message').textContent === ''")


def test_another_operators_quality_settings_hold_in_the_form(
    page: Any, live: BackgroundServer, runs: list[RunRead]
) -> None:
    """Was: the inputs flipped back to the settings of when the page loaded at each status event."""
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.set_quality(runs[0].id, redundancy=2, gold_rate=0.1)
        page.wait_for_function("document.querySelector('#quality-redundancy').value === '2'", timeout=15_000)
        operator.set_feedback_policy(runs[0].id, 45.0)  # a run event: showRun again
        page.wait_for_function("document.querySelector('#policy-text').textContent === 'continue after 45 s'")
        assert page.input_value("#quality-redundancy") == "2" and page.input_value("#quality-gold") == "10"
        operator.set_quality(runs[0].id, redundancy=1, gold_rate=0.0)


def test_a_run_whose_trainer_is_silent_says_so_in_its_header_and_the_title_names_the_run(
    page: Any, live: BackgroundServer, runs: list[RunRead]
) -> None:
    assert page.title() == f"collie · run #{runs[0].id} training"
    assert page.text_content("#run-heard") == ""
    with live.app.state.db.write() as conn:  # its trainer's last call, six minutes ago
        conn.execute(Run.__table__.update().where(Run.id == runs[0].id).values(trainer_seen_at=time.time() - 360))
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.set_feedback_policy(runs[0].id, 30.0)  # a change: the runs list's poll answers now
    page.wait_for_function("document.querySelector('#run-heard').textContent.startsWith('no word from its trainer')")
    assert page.text_content("#run-heard") == "no word from its trainer since 6 min ago"
    open_run(page, runs[1].id)  # was: run 1's word shown for run 2 until the list's next poll (20 s)
    assert page.text_content("#run-heard") == ""


def test_runs_open_from_the_keyboard(page: Any, runs: list[RunRead]) -> None:
    page.focus(f'#runs-body tr[data-run-id="{runs[1].id}"]')
    page.keyboard.press("Enter")
    page.wait_for_function(f"document.querySelector('#run-title').textContent.startsWith('Run #{runs[1].id} ')")
    assert page.evaluate("document.activeElement.tabIndex") == 0


def test_a_stopped_run_offers_no_instructions_and_says_its_queue_is_closed(
    page: Any, live: BackgroundServer, trainer: CollieClient
) -> None:
    stopped = trainer.create_run(make_run_spec())
    with CollieClient(live.url, TOKENS["operator"]) as operator:
        operator.stop(stopped.id)
    page.wait_for_selector(f'#runs-body tr[data-run-id="{stopped.id}"]')
    open_run(page, stopped.id)
    page.wait_for_function("document.querySelector('#instructions-text').disabled")
    assert not page.is_enabled("#instructions-apply")
    page.wait_for_function("document.querySelector('#labeling-body').textContent.includes('takes no more labels')")
    assert "waiting for a labeler" not in page.text_content("#labeling-body")
