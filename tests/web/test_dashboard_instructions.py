"""An operator's instructions for a run's labelers, from the dashboard (Debian's Chromium against a
live service). Was: only `PUT /api/runs/{id}/instructions` set them; the page neither showed nor
changed them."""

from __future__ import annotations

from typing import Any

from service.conftest import TOKENS, make_run_spec, make_session

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MAX_INSTRUCTIONS

from .conftest import operator_page

WAIT_MS = 30_000


def test_an_operator_reads_sends_and_removes_the_instructions(
    live: BackgroundServer, browser: Any, trainer: CollieClient, operator: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec())
    trainer.post_session(run.id, make_session(0, 2))
    operator.set_instructions(run.id, "first words")
    with operator_page(browser, f"{live.url}/?token={TOKENS['operator']}#run={run.id}", wait_ms=WAIT_MS) as page:
        page.wait_for_function("document.querySelector('#instructions-text').value === 'first words'")
        page.fill("#instructions-text", "  a state in the red region is bad, even for a moment  ")
        page.click("#instructions-apply")
        page.wait_for_function("document.querySelector('#instructions-message').textContent.startsWith('sent')")
        assert trainer.run(run.id).instructions == "a state in the red region is bad, even for a moment"
        assert page.input_value("#instructions-text") == trainer.run(run.id).instructions  # as stored, trimmed
        page.fill("#instructions-text", "x" * (MAX_INSTRUCTIONS + 1))
        page.click("#instructions-apply")
        page.wait_for_function(
            f"document.querySelector('#instructions-message').textContent === "
            f"'at most {MAX_INSTRUCTIONS} characters (this is {MAX_INSTRUCTIONS + 1})'"
        )
        assert trainer.run(run.id).instructions.startswith("a state")  # nothing sent
        page.fill("#instructions-text", "")
        page.click("#instructions-apply")
        page.wait_for_function("document.querySelector('#instructions-message').textContent === 'removed'")
        assert trainer.run(run.id).instructions == ""
