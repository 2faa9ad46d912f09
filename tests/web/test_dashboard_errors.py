"""What the dashboard says when it cannot show what was asked, in Debian's Chromium against a live
service: a token the service refuses, a link to a run that does not exist, and a service that stops
answering."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from service.conftest import TOKENS, make_run_spec
from service.test_cli import start_serve, stop

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MetricsIn, RunRead

from .conftest import operator_page

WAIT_MS = 30_000


@pytest.fixture(scope="module")
def run(trainer: CollieClient) -> RunRead:
    return trainer.create_run(make_run_spec())


def test_a_wrong_token_says_so_once_and_disables_the_forms(browser: Any, live: BackgroundServer, run: RunRead) -> None:
    with operator_page(browser, f"{live.url}/?token=not-a-token#run={run.id}", wait_ms=WAIT_MS) as page:
        page.wait_for_selector("#token-form:not([hidden])")
        page.wait_for_load_state("networkidle")  # every refused request answered: nothing left to overwrite
        hint = "this token was refused: paste an operator token above"
        assert page.text_content("#runs-body").startswith(hint)
        assert page.text_content("#labelers-body") == page.text_content("#runs-body")  # one message
        assert page.is_disabled("#labeler-name") and page.is_disabled("#labeler-create")
        assert page.text_content("#token-error") == "token refused: unknown or revoked token"  # the reason
        assert page.is_hidden("#run")
        assert page.text_content("#connection") == "token refused"
        page.fill("#token-input", TOKENS["operator"])  # a valid token: everything comes back
        page.click("#token-form button")
        page.wait_for_selector('#labelers-body tr[data-labeler="operator"]')
        page.wait_for_selector("#run:not([hidden])")
        assert page.is_enabled("#labeler-name") and page.is_enabled("#labeler-create")
        page.wait_for_selector("#token-form", state="hidden")  # with the runs list's answer, which may come last


def test_a_link_to_a_missing_run_says_so_where_the_run_would_be_shown(
    browser: Any, live: BackgroundServer, trainer: CollieClient, run: RunRead
) -> None:
    with operator_page(browser, f"{live.url}/?token={TOKENS['operator']}#run=99", wait_ms=WAIT_MS) as page:
        asked: list[str] = []
        page.on("request", lambda r: asked.append(r.url) if "/api/dashboard/runs/99" in r.url else None)
        with page.expect_response(lambda r: "/api/dashboard/runs/99" in r.url):
            page.reload()  # counted from the start
        epoch = f"document.querySelector('#runs-body tr[data-run-id=\"{run.id}\"]')?.cells[5].textContent"
        page.wait_for_function(f"{epoch} === '0'")
        trainer.post_metrics(run.id, MetricsIn(epoch=7, values={"n_labels": 0.0}))  # the runs list changes
        page.wait_for_function(f"{epoch} === '7'")
        page.wait_for_timeout(500)  # time for a second request, were one sent
        assert len(asked) == 1
        page.wait_for_function("document.querySelector('#connection').textContent === 'live'")  # the connection's
        said = "Run #99: no such run on this service — pick one from the runs above."
        assert page.is_visible("#run-problem") and page.text_content("#run-problem") == said
        assert page.is_hidden("#run")
        problem, runs, labelers = (page.locator(s).bounding_box() for s in ("#run-problem", "#runs", "#labelers"))
        assert problem is not None and runs is not None and labelers is not None
        assert runs["y"] < problem["y"] < labelers["y"]  # where a run goes: below the runs, above the labelers
        page.evaluate(f"window.location.hash = '#run={run.id}'")  # a run that exists
        page.wait_for_selector("#run:not([hidden])")
        assert page.is_hidden("#run-problem")


def test_a_link_that_names_no_run_number_says_so(browser: Any, live: BackgroundServer, run: RunRead) -> None:
    """Was: "#run=abc" ignored, and the newest run shown as if it had been asked for."""
    with operator_page(browser, f"{live.url}/?token={TOKENS['operator']}#run=abc", wait_ms=WAIT_MS) as page:
        page.wait_for_selector("#run-problem:not([hidden])")
        said = '"#run=abc" names no run (a run is a number, as #run=3) — pick one from the runs above.'
        assert page.text_content("#run-problem") == said and page.is_hidden("#run")
        page.click(f'#runs-body tr[data-run-id="{run.id}"]')  # a run picked from the list opens
        page.wait_for_selector("#run:not([hidden])")
        assert page.is_hidden("#run-problem")
        page.evaluate("window.location.hash = 'run=%'")  # no escape at all: was a URIError each poll
        page.wait_for_function(
            "document.querySelector('#run-problem').textContent.startsWith('\"#run=%\" names no run')"
        )
        page.wait_for_selector(f'#runs-body tr[data-run-id="{run.id}"]')  # the list is still drawn
        assert page.text_content("#connection") == "live"


def test_a_service_that_stops_answering_is_said_not_responding(browser: Any, tmp_path: Path) -> None:
    """A frozen service keeps its connections open: the stream sees no error. Was: the badge said
    "live" through 75 s of a service stopped with SIGSTOP. Read from the runs list's long poll, not
    a health check of its own (which would wait for a free connection where tabs hold them all)."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    server, _ = start_serve(tmp_path / "frozen.db", tmp_path / "tokens.json", env)
    try:
        info = json.loads((tmp_path / "tokens.json").read_text())
        with CollieClient(info["api"], info["tokens"]["trainer"]) as trainer:
            run = trainer.create_run(make_run_spec())
        url = f"{info['api']}/?token={info['tokens']['operator']}#run={run.id}"
        with operator_page(browser, url, wait_ms=WAIT_MS) as page:
            page.wait_for_function("document.querySelector('#connection').textContent === 'live'")
            server.send_signal(signal.SIGSTOP)
            try:  # the runs list's long poll (20 s) is 10 s overdue
                page.wait_for_function(
                    "document.querySelector('#connection').textContent === 'not responding'", timeout=45_000
                )
            finally:
                server.send_signal(signal.SIGCONT)
            page.wait_for_function("document.querySelector('#connection').textContent === 'live'")
    finally:
        stop(server)


def test_a_service_restarted_on_its_port_is_not_said_not_responding(browser: Any, tmp_path: Path) -> None:
    """`collie up` restarts a service that died on the port it keeps open. The browser re-sends the
    runs list's long poll that the death cut into that port, where it waits for the new service and
    then its full 20 s: the badge said "not responding" of a service that was up again (the poll's
    timer ran from the first send). A poll cut by a connection change gets another window."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    listening = socket.create_server(("127.0.0.1", 0))
    port, fd = listening.getsockname()[1], listening.fileno()
    db, tokens = tmp_path / "restarted.db", tmp_path / "tokens.json"

    def serve() -> subprocess.Popen[bytes]:
        command = [sys.executable, "-m", "collie.cli", "serve", "--fd", str(fd), "--db", str(db)]
        return subprocess.Popen([*command, "--tokens-json", str(tokens)], env=env, pass_fds=(fd,))

    server = serve()
    try:
        deadline = time.monotonic() + 60
        while not tokens.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        minted = json.loads(tokens.read_text())["tokens"]
        api = f"http://127.0.0.1:{port}"
        with CollieClient(api, minted["trainer"]) as trainer:
            run = trainer.create_run(make_run_spec())
        with operator_page(browser, f"{api}/?token={minted['operator']}#run={run.id}", wait_ms=WAIT_MS) as page:
            page.wait_for_function("document.querySelector('#connection').textContent === 'live'")
            page.evaluate(
                """() => { window.badges = []; const badge = document.querySelector('#connection');
                new MutationObserver(() => window.badges.push(badge.textContent))
                  .observe(badge, {childList: true, characterData: true, subtree: true}); }"""
            )
            time.sleep(8)  # the runs poll is well into its 20 s wait
            server.kill()
            server.wait(10)
            time.sleep(3)
            server = serve()
            page.wait_for_function("window.badges.includes('reconnecting…')")
            time.sleep(35)  # past the first poll's 30 s, counted from its first send
            badges = page.evaluate("window.badges")
            assert "not responding" not in badges, badges
            assert page.text_content("#connection") == "live"
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(20)
        listening.close()
