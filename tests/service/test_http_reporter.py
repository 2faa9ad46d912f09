"""The trainer's telemetry says why a report was not delivered: a service too busy or unreachable to
answer (best effort, expected on a busy machine) reads differently from a refusal (a defect or a
revoked token), so a log can be checked for the second alone."""

from __future__ import annotations

import socket

import pytest

from backend.server import BackgroundServer
from collie.client import CollieClient
from trainer.feedback.http_reporter import HttpReporter
from trainer.telemetry import MetricsReport

from .conftest import TOKENS, make_run_spec

BUSY = "not delivered (the service is busy or unreachable; best effort): "


def test_an_unreachable_service_and_a_refusal_are_told_apart(
    live: BackgroundServer, trainer: CollieClient, caplog: pytest.LogCaptureFixture
) -> None:
    run = trainer.create_run(make_run_spec())
    nobody = socket.socket()  # bound, never listening: every connection to it is refused
    nobody.bind(("127.0.0.1", 0))
    unreachable = HttpReporter(f"http://127.0.0.1:{nobody.getsockname()[1]}", TOKENS["trainer"], run.id, timeout_s=2.0)
    refused = HttpReporter(live.url, "not-a-token", run.id)
    with caplog.at_level("WARNING", logger="trainer.feedback.http_reporter"):
        unreachable.metrics(MetricsReport(1, {"return": 1.0}))
        refused.metrics(MetricsReport(1, {"return": 1.0}))
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 2, said
    assert said[0].startswith(f"report metrics {BUSY}"), said[0]
    assert said[1].startswith("report metrics not delivered: ") and "401" in said[1], said[1]
    for reporter in (unreachable, refused):
        reporter.close()
    nobody.close()
