"""`collie up --host 0.0.0.0`: people on other machines label and watch. The service and the
labeling UI listen on every interface, the links name this machine's address on its network
(not 127.0.0.1, which would be the labeler's own machine), and a labeler's browser labels there."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest
from playwright.sync_api import Browser

from collie.addresses import network_address
from collie.client import CollieClient

from .page import TIMEOUT_S, open_labeler, wait_segment

pytestmark = pytest.mark.slow  # a whole stack and a browser: started first under make test's two workers


def test_a_labeler_on_the_network_labels_through_the_printed_link(tmp_path: Path, browser: Browser) -> None:
    shown = network_address()
    if shown is None:  # the links would name this machine's hostname, which resolves to itself
        pytest.skip("this machine has no network address to reach the stack at")
    cmd = [sys.executable, "-m", "collie.cli", "up", "--host", "0.0.0.0", "--port", "0", "--ui-port", "0"]
    cmd += ["--preset", "smoke", "--out", str(tmp_path), "--info-json", str(tmp_path / "info.json")]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 180
        while not (tmp_path / "info.json").exists():
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail(proc.communicate()[1][-3000:])
            time.sleep(0.1)
        meta = json.loads((tmp_path / "info.json").read_text())
        for name in ("api", "labeling_ui", "dashboard"):
            assert urlsplit(meta[name]).hostname == shown, meta[name]
        page = open_labeler(browser, meta["labeling_ui"])  # the labeler's link, from the network's side
        wait_segment(page)
        with CollieClient(meta["api"], meta["tokens"]["operator"]) as client:
            deadline = time.monotonic() + TIMEOUT_S
            while not client.label_events(meta["run_id"]):  # a key too soon after the segment appeared waits
                assert time.monotonic() < deadline, page.inner_text("body")[-2000:]
                page.keyboard.press("2")
                time.sleep(0.5)
            assert client.label_events(meta["run_id"])[0].value == 1  # key 2: neutral (north never calls a state good)
        page.context.close()
        dashboard = httpx.get(meta["dashboard"], timeout=30)
        assert dashboard.status_code == 200 and "<html" in dashboard.text.lower()
        token = {"Authorization": f"Bearer {meta['tokens']['operator']}"}
        assert httpx.get(f"{meta['api']}/api/runs/{meta['run_id']}", headers=token, timeout=30).status_code == 200
        ui_port = urlsplit(meta["labeling_ui"]).port
        assert httpx.get(f"http://127.0.0.1:{ui_port}/", timeout=30).status_code == 200  # and from here
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
    assert proc.returncode in (0, 130), err[-3000:]
    assert "reachable from other machines on 0.0.0.0" in out and f"label     http://{shown}:" in out
    assert "give each colleague their own (dashboard → Labelers)" in out
