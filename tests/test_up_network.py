"""`collie up --host 0.0.0.0`: people on other machines label and watch. The service and the
labeling UI listen on every interface, the links name this machine's address on its network
(not 127.0.0.1, which would be the labeler's own machine), and they answer there."""

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

from collie.up import public_address


def test_a_stack_on_every_interface_hands_out_links_that_answer_there(tmp_path: Path) -> None:
    shown = public_address("0.0.0.0")
    assert not shown.startswith("127."), "this machine has no network to test on"
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
        page = httpx.get(meta["labeling_ui"], timeout=30)  # the labeler's link, from the network's side
        assert page.status_code == 200 and "<html" in page.text.lower()
        dashboard = httpx.get(meta["dashboard"], timeout=30)
        assert dashboard.status_code == 200 and "<html" in dashboard.text.lower()
        token = {"Authorization": f"Bearer {meta['tokens']['operator']}"}
        assert httpx.get(f"{meta['api']}/api/runs/{meta['run_id']}", headers=token, timeout=30).status_code == 200
        ui_port = urlsplit(meta["labeling_ui"]).port
        assert httpx.get(f"http://127.0.0.1:{ui_port}/", timeout=30).status_code == 200  # and from here
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    assert proc.returncode in (0, 130), err[-3000:]
    assert "reachable from other machines on 0.0.0.0" in out and f"label     http://{shown}:" in out
