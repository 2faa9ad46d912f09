"""Security headers on the API and the dashboard (CSP, nosniff, frame-ancestors, no referrer), and
the dashboard still works under its policy in Debian's Chromium: it draws its plots and the
browser reports no policy violation."""

from __future__ import annotations

from typing import Any

import httpx
from chromium import chromium

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MetricsIn, Rollout, RolloutsIn

from .conftest import TOKENS, make_run_spec

EXPECTED = {"x-content-type-options": "nosniff", "referrer-policy": "no-referrer", "x-frame-options": "DENY"}


def test_every_answer_carries_the_headers(live: BackgroundServer) -> None:
    auth = {"Authorization": f"Bearer {TOKENS['operator']}"}
    answers = [
        httpx.get(f"{live.url}/"),
        httpx.get(f"{live.url}/js/main.js"),
        httpx.get(f"{live.url}/api/health"),
        httpx.get(f"{live.url}/api/runs", headers=auth),
        httpx.get(f"{live.url}/api/runs"),  # a 401
        httpx.post(f"{live.url}/api/runs", headers=auth, content=b"x" * (2 * 1024 * 1024)),  # a 413
    ]
    assert [a.status_code for a in answers] == [200, 200, 200, 200, 401, 413]
    for answer in answers:
        for name, value in EXPECTED.items():
            assert answer.headers.get(name) == value, (answer.url, name)
        csp = answer.headers["content-security-policy"]
        assert "frame-ancestors 'none'" in csp and "script-src 'self'" in csp and "unsafe-eval" not in csp


def test_the_dashboard_works_under_its_policy(live: BackgroundServer, trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec())
    trainer.post_metrics(run.id, MetricsIn(epoch=1, values={"return": 1.0}))
    trainer.post_metrics(run.id, MetricsIn(epoch=2, values={"return": 2.0}))
    path = [[0.0, 0.0], [0.5, 0.2], [1.0, 0.4]]
    trainer.post_rollouts(run.id, RolloutsIn(epoch=2, rollouts=[Rollout(skill=[1.0, 0.0], xy=path)]))
    problems: list[str] = []
    with chromium() as browser:
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page.set_default_timeout(60_000)

        def console(message: Any) -> None:
            if "Content Security Policy" in message.text or "Refused to" in message.text:
                problems.append(message.text)

        page.on("console", console)
        page.add_init_script(
            "window.__violations = []; document.addEventListener('securitypolicyviolation',"
            " (e) => window.__violations.push(e.violatedDirective + ' ' + e.blockedURI));"
        )
        page.goto(f"{live.url}/?token={TOKENS['operator']}#run={run.id}")
        page.wait_for_selector("#map .main-svg")  # Plotly drew the skills map
        page.wait_for_selector("#curves .main-svg")
        violations = page.evaluate("window.__violations || []")
        page.close()
    assert problems == [] and violations == []
