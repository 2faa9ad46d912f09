"""The dashboard in Debian's Chromium against a live `smoke` run of real processes: `collie up`
starts the service, the trainer and the oracle teacher, each its own process talking HTTP.
The tests share the run and go in order: watch it train, pause and resume it, try a wrong token,
stop it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from collie.client import CollieClient

pytestmark = pytest.mark.slow
START_S = 240.0  # the trainer imports torch and MuJoCo; generous for a busy machine
WAIT_MS = 120_000


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    out = tmp_path_factory.mktemp("up")
    info = out / "info.json"
    command = [
        sys.executable,
        "-m",
        "collie.cli",
        "up",
        "--env",
        "point",
        "--task",
        "north",
        "--teacher",
        "oracle",
        "--preset",
        "smoke",
        "--port",
        "0",
        "--out",
        str(out),
        "--info-json",
        str(info),
        "--no-label-ui",
        "--train-args=--epochs 100000 --eval-every 2",
    ]  # long enough to pause; evaluated often
    with open(out / "up.log", "wb") as log:
        proc = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            deadline = time.monotonic() + START_S
            while not info.exists():
                assert proc.poll() is None, (out / "up.log").read_text()[-3000:]
                assert time.monotonic() < deadline, "collie up did not start"
                time.sleep(0.2)
            yield json.loads(info.read_text())
        finally:
            proc.send_signal(signal.SIGINT)  # collie up stops its children
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.fixture(scope="module")
def page(stack: dict[str, Any], browser: Any) -> Iterator[Any]:
    # bypass_csp: Playwright's wait_for_function evaluates strings, which the dashboard's policy
    # forbids (tests/service/test_security_headers.py checks the page works under it)
    page = browser.new_page(bypass_csp=True, viewport={"width": 1400, "height": 1500})
    page.set_default_timeout(WAIT_MS)  # a busy machine renders slowly
    page.goto(f"{stack['api']}/?token={stack['tokens']['operator']}")
    yield page
    page.close()


def number(page: Any, selector: str, attribute: str | None = None) -> int:
    value = page.get_attribute(selector, f"data-{attribute}") if attribute else page.text_content(selector)
    return int(value or 0)


def test_trajectories_appear_and_update_while_training(stack: dict[str, Any], page: Any, artifacts: Path) -> None:
    assert "token=" not in page.url  # the token leaves the address bar (history, screenshots)
    page.wait_for_function("document.querySelector('#map').dataset.trajectories === '8'")
    first = number(page, "#map", "epoch")
    page.wait_for_function(f"Number(document.querySelector('#map').dataset.epoch) > {first}")
    page.wait_for_function("Number(document.querySelector('#map').dataset.labelled) > 0")
    names = page.evaluate("document.querySelector('#map').data.map((t) => t.name || '')")  # Plotly's traces
    assert {n.split(" (")[0] for n in names if n.startswith("labelled")} == {  # names from the service
        "labelled bad",
        "labelled neutral",
        "labelled good",
    }
    assert page.locator("#runs-body tr[data-run-id]").count() == 1
    assert page.locator("#labeling-body").inner_text().count("labeler") >= 1
    page.screenshot(path=str(artifacts / "dashboard.png"), full_page=True)
    with CollieClient(stack["api"], stack["tokens"]["operator"]) as client:  # once guidance starts, w(s) comes
        deadline = time.monotonic() + WAIT_MS / 1000
        while "w" not in (latest := client.rollouts(stack["run_id"], limit=1)[0]).rollouts[0].extra:
            assert time.monotonic() < deadline, "no w(s) in the trainer's rollouts"
            time.sleep(1)
    page.select_option("#colour-by", "w")
    page.wait_for_function(f"Number(document.querySelector('#map').dataset.epoch) >= {latest.epoch}")
    page.wait_for_function("!document.querySelector('#map-note').textContent.includes('no w(s)')")
    page.screenshot(path=str(artifacts / "dashboard-w.png"), full_page=True)


def test_pause_stops_the_epoch_counter_and_resume_restarts_it(stack: dict[str, Any], page: Any) -> None:
    answers: list[tuple[Any, Any]] = []  # the answer to "pause", held: it comes after the trainer's "paused"
    page.route("**/api/runs/*/pause", lambda route: answers.append((route, route.fetch())))
    page.click("#pause")
    page.wait_for_function("document.body.dataset.runStatus === 'paused'")  # from the stream
    route, answer = answers[0]
    with page.expect_response("**/api/runs/*/pause"):
        route.fulfill(response=answer)  # late, as on a busy machine
    page.unroute("**/api/runs/*/pause")
    page.wait_for_function("document.body.dataset.runControl === 'pause'")
    page.wait_for_timeout(500)  # the late answer handled: it must not undo the stream's news
    assert page.get_attribute("body", "data-run-status") == "paused"
    held = number(page, "#run-epoch")
    page.wait_for_timeout(4000)  # several epochs' worth on this preset
    assert number(page, "#run-epoch") == held and page.is_enabled("#resume") and not page.is_enabled("#pause")
    page.click("#resume")
    page.wait_for_function(f"Number(document.querySelector('#run-epoch').textContent) > {held}")
    assert page.get_attribute("body", "data-run-control") == "run"


def test_a_labeler_token_is_offered_no_control_and_a_wrong_token_none(stack: dict[str, Any], browser: Any) -> None:
    api, run_id = stack["api"], stack["run_id"]
    labeler = browser.new_page(bypass_csp=True)  # a labeler's token may watch, not steer
    labeler.set_default_timeout(WAIT_MS)
    labeler.goto(f"{api}/?token={stack['tokens']['labeler']}")
    labeler.wait_for_function("document.body.dataset.runControl === 'run'")
    labeler.wait_for_function("document.body.dataset.role === 'labeler'")
    # the page offers none of what the service would refuse it (was: each answered 403 when clicked)
    for hidden in ("#pause", "#stop", "#policy", "#quality", "#labeler-form", "#disagreements"):
        assert not labeler.is_visible(hidden), hidden
    assert "take an operator's token" in labeler.text_content("#role-note")
    assert labeler.locator("#runs-body tr[data-run-id]").count() >= 1  # the runs it may see, as before
    labeler.close()
    refused = httpx.post(
        f"{api}/api/runs/{run_id}/pause", headers={"Authorization": f"Bearer {stack['tokens']['labeler']}"}
    )
    assert refused.status_code == 403
    stranger = browser.new_page(bypass_csp=True)
    stranger.set_default_timeout(WAIT_MS)
    stranger.goto(f"{api}/?token=not-a-token")
    stranger.wait_for_selector("#token-form:not([hidden])")
    assert "unknown or revoked token" in stranger.text_content("#token-error")
    assert stranger.locator("#runs-body tr[data-run-id]").count() == 0
    assert "paste an operator token" in stranger.text_content("#runs-body")
    assert stranger.text_content("#connection") == "token refused"
    stranger.goto(f"{api}/")  # a fresh tab with no token at all
    stranger.evaluate("sessionStorage.clear()")
    stranger.reload()
    stranger.wait_for_function("document.querySelector('#labelers-body').textContent.includes('no token')")
    stranger.close()
    refused = httpx.post(f"{api}/api/runs/{run_id}/pause", headers={"Authorization": "Bearer not-a-token"})
    assert refused.status_code == 401
    with CollieClient(api, stack["tokens"]["operator"]) as client:
        assert client.run(run_id).control == "run"


def test_a_link_to_a_run_that_does_not_exist_says_so_where_the_run_was(stack: dict[str, Any], browser: Any) -> None:
    page = browser.new_page(bypass_csp=True)
    page.set_default_timeout(WAIT_MS)
    page.goto(f"{stack['api']}/?token={stack['tokens']['operator']}#run={stack['run_id']}")
    page.wait_for_selector("#run:not([hidden])")
    page.evaluate("window.location.hash = '#run=99999'")  # from an open run to one that does not exist
    page.wait_for_function("document.querySelector('#run-problem').textContent.startsWith('Run #99999: no such run')")
    assert page.is_visible("#run-problem") and page.is_hidden("#run")
    page.wait_for_function("document.querySelector('#connection').textContent === 'live'")  # the connection's
    page.wait_for_selector(f"#runs-body tr[data-run-id='{stack['run_id']}']")  # the runs to pick from
    page.close()


def test_a_run_whose_trainer_falls_silent_says_so(stack: dict[str, Any], page: Any) -> None:
    mark = f"document.querySelector(\"#runs-body tr[data-run-id='{stack['run_id']}'] .heard\")"
    page.wait_for_function(f"{mark} !== null")
    with CollieClient(stack["api"], stack["tokens"]["operator"]) as client:
        assert client.run(stack["run_id"]).trainer_seen_at is not None  # the live trainer was heard
    time.sleep(1.5)  # a tick
    assert page.evaluate(f"{mark}.textContent") == ""  # a live trainer: nothing to say
    page.evaluate("window.realNow = Date.now; Date.now = () => window.realNow() + 360e3")
    try:  # the page's clock six minutes on: its trainer's last call looks six minutes old
        page.wait_for_function(f"{mark}?.textContent.startsWith('no word from its trainer since 6 min ago')")
    finally:
        page.evaluate("Date.now = window.realNow")


def test_stop_finishes_the_run(stack: dict[str, Any], page: Any) -> None:
    page.click("#stop")
    assert page.text_content("#stop") == "Really stop?"
    page.click("#stop")
    page.wait_for_function("document.body.dataset.runStatus === 'finished'")
    page.wait_for_function("document.querySelector('#runs-body .status')?.textContent === 'stopped'")
    assert page.text_content("#run-status").startswith("stopped")  # not "finished": the operator ended it
    assert all(not page.is_enabled(b) for b in ("#pause", "#resume", "#stop"))
