"""Discarding a careless labeler's labels from the dashboard, in Debian's Chromium against a live
service: the first click arms the labeler's button, the second withdraws their labels (the trainer
is told), the panel says what happened and counts them no more."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from service.conftest import TOKENS, make_run_spec, make_session

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import RunRead, WithdrawnEvent

from .conftest import operator_page

WAIT_MS = 30_000


@pytest.fixture(scope="module")
def run(live: BackgroundServer, trainer: CollieClient, operator: CollieClient) -> RunRead:
    """Four queries: two labelled by a careless labeler, one by a careful one, one for a newcomer."""
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 4))
    for name, values in (("careless-web", [0, 0]), ("careful-web", [1])):
        with CollieClient(live.url, operator.create_labeler(name).token) as client:
            for value in values:
                claim = client.claim(created.id)
                assert claim is not None
                client.submit(created.id, claim.query.query_id, value)  # type: ignore[arg-type]
    return created


@pytest.fixture(scope="module")
def page(live: BackgroundServer, browser: Any, run: RunRead) -> Iterator[Any]:
    with operator_page(browser, f"{live.url}/?token={TOKENS['operator']}#run={run.id}", wait_ms=WAIT_MS) as page:
        page.wait_for_selector('#labelers-stats tr[data-labeler="careless-web"]')
        yield page


def labels_of(page: Any, name: str) -> str:
    return page.inner_text(f'#labelers-stats tr[data-labeler="{name}"] td.labels')


def test_two_clicks_discard_a_labelers_labels(page: Any, trainer: CollieClient, run: RunRead) -> None:
    assert labels_of(page, "careless-web") == "2"
    button = '#labelers-stats tr[data-labeler="careless-web"] button[data-discard]'
    page.click(button)  # arms only
    page.wait_for_function(f"document.querySelector('{button}')?.textContent === 'Confirm: discard 2'")
    assert trainer.run(run.id).n_labels == 3
    page.click(button)
    page.wait_for_function(
        "document.querySelector('#discard-message')?.textContent.startsWith('discarded 2 labels of careless-web')"
    )
    page.wait_for_function(
        "document.querySelector('#labelers-stats tr[data-labeler=\"careless-web\"] td.labels')?.textContent === '0'"
    )
    assert page.query_selector(button) is None  # nothing left to discard
    assert labels_of(page, "careful-web") == "1"
    state = trainer.run(run.id)
    assert state.n_labels == 1 and state.queue.pending == 3
    withdrawn = [e.data.query_id for e in trainer.events(run.id).events if isinstance(e, WithdrawnEvent)]
    assert len(withdrawn) == 2


def test_an_armed_button_stays_armed_through_a_live_update(
    page: Any, live: BackgroundServer, operator: CollieClient, run: RunRead
) -> None:
    careful = '#labelers-stats tr[data-labeler="careful-web"] button[data-discard]'
    page.click(careful)
    page.wait_for_function(f"document.querySelector('{careful}')?.textContent === 'Confirm: discard 1'")
    with CollieClient(live.url, operator.create_labeler("newcomer-web").token) as newcomer:
        claim = newcomer.claim(run.id)
        assert claim is not None
        newcomer.submit(run.id, claim.query.query_id, 1)  # the panel redraws from the stream
    page.wait_for_selector('#labelers-stats tr[data-labeler="newcomer-web"]')
    assert page.inner_text(careful) == "Confirm: discard 1"
    page.click(careful)
    page.wait_for_function(
        "document.querySelector('#discard-message')?.textContent.startsWith('discarded 1 label of careful-web')"
    )
    assert labels_of(page, "newcomer-web") == "1"


def test_a_stopped_run_offers_no_discard(
    page: Any, live: BackgroundServer, operator: CollieClient, run: RunRead
) -> None:
    """Was: the button stayed, and its second click answered that a stopped run keeps its labels."""
    newcomer = '#labelers-stats tr[data-labeler="newcomer-web"]'
    page.wait_for_selector(f"{newcomer} button[data-discard]")
    operator.stop(run.id)
    page.wait_for_function(f"document.querySelector('{newcomer} button[data-discard]') === null")
    assert labels_of(page, "newcomer-web") == "1"  # the labels are still shown, only not discardable
