"""The oracle teacher labels through the API with a labeler token, by the task rule."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import threading
import time

import httpx
import numpy as np
import pytest
from canned_http import answering

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.tasks import get_task
from collie.teacher import OracleTeacher
from teacher import TeacherLoop, oracle_for, segment_label
from trainer.feedback.http import HttpFeedback
from trainer.telemetry import StatusReport

from .conftest import TOKENS, make_run_spec, make_session, settings_for
from .postgres import PostgresServer
from .test_http_feedback import segments


def expected(client: CollieClient, run_id: int) -> dict[str, int]:
    oracle = OracleTeacher(get_task("north", "point"))
    return {q.query_id: segment_label(oracle, client.query(run_id, q.query_id)) for q in client.queries(run_id)}


def test_cli_labels_every_query_by_the_rule(live: BackgroundServer, trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec(task="north"))
    session = make_session(0, 6)
    for i, q in enumerate(session.queries):  # spread the paths over the plane: all three labels occur
        q.xy = (np.asarray(q.xy) * 0.1 + [[(-1) ** i * 3.0, 5.0 - 2 * i]]).tolist()
    trainer.post_session(run.id, session)
    command = [sys.executable, "-m", "collie.cli", "teacher", "--api", live.url, "--run", str(run.id)]
    out = subprocess.run(
        [*command, "--token", TOKENS["labeler"]], capture_output=True, text=True, timeout=60, check=True
    )
    assert "labelled 6 queries" in out.stdout
    got = {e.query_id: e.label for e in trainer.effective_labels(run.id)}
    assert got == expected(trainer, run.id)
    assert {e.labeler for e in trainer.label_events(run.id)} == {"labeler"}


def test_a_token_the_service_refuses_to_label_with_is_one_line(live: BackgroundServer, trainer: CollieClient) -> None:
    run = trainer.create_run(make_run_spec(task="north"))
    trainer.post_session(run.id, make_session(0, 2))
    command = [sys.executable, "-m", "collie.cli", "teacher", "--api", live.url, "--run", str(run.id)]
    out = subprocess.run([*command, "--token", TOKENS["trainer"]], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert (
        out.stderr.startswith(f"collie teacher: error: the labeling service at {live.url} refused the token (403")
        and "(after 0 labels)" in out.stderr
    )


def test_what_keeps_the_teacher_from_the_service_is_one_line_naming_it(live: BackgroundServer) -> None:
    """Was: "GET /runs/1: ConnectError('[Errno 111] Connection refused')", "404: Not Found", and
    a refused token's "401: …" with status 1 and no "error:"."""
    with socket.socket() as gone:
        gone.bind(("127.0.0.1", 0))
        nobody = f"http://127.0.0.1:{gone.getsockname()[1]}"  # bound, never listening: refused
        cases = [
            (nobody, TOKENS["labeler"], f"the labeling service at {nobody} does not answer (connection refused)"),
            (
                f"{live.url}/zzz",
                TOKENS["labeler"],
                f"{live.url}/zzz is not a collie service (404 on /zzz/api/runs/999999)",
            ),
            (live.url, "wrong-token-0123456789", f"the labeling service at {live.url} refused the token (401: unknown"),
            (live.url, TOKENS["labeler"], f"the labeling service at {live.url} has no run 999999"),
        ]
        for api, token, said in cases:
            command = [sys.executable, "-m", "collie.cli", "teacher", "--api", api, "--run", "999999", "--token", token]
            out = subprocess.run(command, capture_output=True, text=True, timeout=60)
            refused = 1 if api == nobody else 2  # no answer: a fault a restart may mend (collie up restarts on 1)
            assert out.returncode == refused and out.stderr.startswith(f"collie teacher: error: {said}"), out.stderr
            assert len(out.stderr.splitlines()) == 1


def teacher(api: str, run_id: int) -> subprocess.CompletedProcess[str]:
    """A real `collie teacher` of run `run_id` at `api`, with the labeler token."""
    command = [sys.executable, "-m", "collie.cli", "teacher", "--api", api, "--run", str(run_id)]
    return subprocess.run([*command, "--token", TOKENS["labeler"]], capture_output=True, text=True, timeout=60)


def test_a_service_busy_at_the_start_is_exit_1_and_the_same_teacher_labels_once_it_is_back() -> None:
    """A real service whose database is down (PostgreSQL stopped under it, as in
    test_database_outage) answers the teacher's first request 503: one line saying it is busy, and
    exit 1, after which `collie up` restarts the teacher (two 2s in a row would end the stack). Was:
    exit 2, "answered 503: …", as for a refusal."""
    pg = PostgresServer().start()  # its own server: the session's one stays up for the others
    try:
        app = create_app(settings_for(pg.new_database(), token_cache_s=0.0))
        with BackgroundServer(app) as server, CollieClient(server.url, TOKENS["trainer"]) as trainer:
            run = trainer.create_run(make_run_spec(task="north"))
            trainer.post_session(run.id, make_session(0, 2))
            pg.halt()
            out = teacher(server.url, run.id)
            said = f"the labeling service at {server.url} is busy or failing now (503: the database is unreachable"
            assert out.returncode == 1 and out.stderr.startswith(f"collie teacher: error: {said}"), out.stderr
            assert len(out.stderr.splitlines()) == 1
            pg.start()
            deadline = time.monotonic() + 60
            while httpx.get(f"{server.url}/api/health").status_code != 200:
                assert time.monotonic() < deadline, "the service did not see the database come back"
                time.sleep(0.1)
            again = teacher(server.url, run.id)  # what `collie up` does after a 1
            assert again.returncode == 0 and "labelled 2 queries" in again.stdout, again.stderr
    finally:
        pg.stop()


def test_a_service_that_answers_429_at_the_start_is_exit_1() -> None:
    """429 (too many requests) is busy too, not a refusal. A real service answers it only for
    too many streams, never for a run: a stand-in answers it."""
    with answering(429, b'{"detail": "slow down"}', {"Retry-After": "1"}) as api:
        out = teacher(api, 1)
    said = f"collie teacher: error: the labeling service at {api} is busy or failing now (429: slow down)\n"
    assert out.returncode == 1 and out.stderr == said, out.stderr


def test_an_answer_damaged_on_the_way_at_the_start_is_one_line_and_exit_1() -> None:
    """A proxy whose body is not the gzip its header says (httpx's DecodingError): transient, as no
    answer is, so `collie up` restarts the teacher. Was: DecodingError's traceback."""
    with answering(200, b"not gzip at all", {"Content-Encoding": "gzip"}) as api:
        out = teacher(api, 1)
    said = (
        f"collie teacher: error: the labeling service at {api} sent an answer damaged on the way, a proxy "
        f"between? (GET {api}/api/runs/1: the body is not in its declared Content-Encoding ("
    )
    assert out.returncode == 1 and out.stderr.startswith(said), out.stderr
    assert len(out.stderr.splitlines()) == 1 and "Traceback" not in out.stderr


def test_a_200_that_is_not_json_at_the_start_is_one_line_and_exit_2() -> None:
    """A proxy's (or another web service's) page with a 200 where the run should be, and on
    /api/health too: not a collie service, a refusal. Was: pydantic's multi-line error."""
    page = b"<html><head><title>Welcome to nginx!</title></head><body>\n</body></html>"
    with answering(200, page, {"Content-Type": "text/html"}) as api:
        out = teacher(api, 1)
    said = (
        f"collie teacher: error: {api} is not a collie service (no run in its answer: GET {api}/api/runs/1 "
        "answered 200 with an HTML page (Welcome to nginx!), not JSON)\n"
    )
    assert out.returncode == 2 and out.stderr == said, out.stderr


@pytest.mark.parametrize(
    ("flags", "said"),
    [
        (["--run", "0"], "argument --run: 0 is not an id: 1 to"),  # was the service's raw 422 error list
        (["--rate", "0"], "argument --rate: 0 must be > 0"),  # as `collie up --teacher-rate 0`
        (["--rate", "-1"], "argument --rate: -1 must be > 0"),
        (["--wait", "-1"], "argument --wait: -1 must be ≥ 0"),
        (["--noise-band", "-1"], "argument --noise-band: -1 must be ≥ 0"),  # was "noise_band must be ≥ 0", later
        (["--seed", "99999999999999999999"], "argument --seed: 99999999999999999999 is more than 4294967295"),
    ],
)
def test_values_the_teacher_cannot_use_are_refused_by_argparse(
    capsys: pytest.CaptureFixture[str], flags: list[str], said: str
) -> None:
    from collie.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["teacher", "--api", "http://127.0.0.1:9", "--run", "1", "--token", TOKENS["labeler"], *flags])
    assert exit_.value.code == 2 and f"collie teacher: error: {said}" in capsys.readouterr().err


def test_a_validation_error_reads_as_one_line_naming_the_field(live: BackgroundServer, labeler: CollieClient) -> None:
    with pytest.raises(ApiError) as refused:
        labeler.run(0)
    assert str(refused.value) == "422: run_id: not a run's number: '0' (digits 0-9 only, 1 to 2147483647)"
    assert isinstance(refused.value.detail, list)  # the service's own detail, kept for callers that read it


def test_ctrl_c_while_waiting_for_the_run_is_one_line() -> None:
    """Ctrl-C where a command has no handler of its own (here `--wait` for the service) ends it with
    a line and status 130, not a traceback."""
    with socket.create_server(("127.0.0.1", 0)) as listener:
        listener.settimeout(60)
        api = f"http://127.0.0.1:{listener.getsockname()[1]}"
        command = [sys.executable, "-m", "collie.cli", "teacher", "--api", api, "--run", "1", "--wait", "60"]
        proc = subprocess.Popen([*command, "--token", TOKENS["labeler"]], stderr=subprocess.PIPE, text=True)
        try:
            conn, _ = listener.accept()
            with conn, conn.makefile("rb") as request:
                assert request.read(4) == b"GET "  # its first request is sent: it waits for the answer
                proc.send_signal(signal.SIGINT)
                _, err = proc.communicate(timeout=60)
        finally:
            proc.kill()
    assert proc.returncode == 130 and "collie teacher: interrupted" in err and "Traceback" not in err, err


def test_until_done_waits_for_new_sessions_and_stops_when_finished(
    live: BackgroundServer, trainer: CollieClient, labeler: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec(task="north"))
    loop = TeacherLoop(labeler, run.id, oracle_for(labeler, run.id, 0.0, 0), idle_wait_s=1.0)
    worker = threading.Thread(target=loop.run, kwargs={"until_done": True}, daemon=True)
    worker.start()
    trainer.post_session(run.id, make_session(0, 3))
    assert labelled_within(trainer, run.id, 3), "the first session was not labelled"
    trainer.post_session(run.id, make_session(1, 2))
    assert labelled_within(trainer, run.id, 5), "the session posted later was not labelled"
    trainer.set_status(run.id, "finished")
    worker.join(30)
    assert not worker.is_alive() and loop.labelled == 5


def labelled_within(client: CollieClient, run_id: int, n: int, timeout_s: float = 60.0) -> bool:
    """Whether the run reaches n labels within timeout_s."""
    deadline = time.monotonic() + timeout_s
    while client.run(run_id).n_labels < n:
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def test_feedback_source_collects_from_the_teacher_with_a_rate(live: BackgroundServer, labeler: CollieClient) -> None:
    source = HttpFeedback.create(live.url, TOKENS["trainer"], make_run_spec(task="north"), wait_chunk_s=2.0)
    loop = TeacherLoop(labeler, source.run_id, oracle_for(labeler, source.run_id, 0.0, 0), rate=20.0, idle_wait_s=1.0)
    worker = threading.Thread(target=loop.run, kwargs={"until_done": True}, daemon=True)
    worker.start()
    started = time.monotonic()
    got = source.collect(0, 0, segments(0, 6))
    assert time.monotonic() - started >= 5 / 20  # six labels at 20 per second
    assert {e.query_id: e.label for e in got} == expected(labeler, source.run_id)
    source.reporter.status(StatusReport("finished", 1))
    worker.join(30)
    assert not worker.is_alive()
    source.close()
