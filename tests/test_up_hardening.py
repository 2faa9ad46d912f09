"""`collie up` under attack and faults, with real processes: tokens never reach a command line, a
log or a file others can read (a token starting with '-' included), and a part killed mid-run is
restarted so the run still finishes."""

import contextlib
import json
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from collie.client import CollieClient

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)


def up_command(out: Path, *more: str) -> list[str]:
    return [
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
        "--ui-port",
        "0",
        "--out",
        str(out),
        "--info-json",
        str(out / "info.json"),
        "--exit-when-done",
        *more,
    ]


# A whole run, shorter than the smoke preset's (8 epochs, 3 sessions of 2 queries): two sessions, at
# epochs 2 and 4, so there is still a middle of the run (some labels given, more to come) to act in.
SHORT_RUN = "--train-args=--epochs 4 --total-queries 4"


def children(out: Path) -> dict[str, int]:
    try:
        return json.loads((out / "children.json").read_text())["children"]
    except (FileNotFoundError, json.JSONDecodeError):
        return {}


@pytest.fixture(scope="module")
def finished_stack(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A stack run to its end once (no labeling UI, 2 epochs: the session at epoch 2, labelled by the
    teacher), for the tests that start from a finished run folder; each takes a copy of its own."""
    out = tmp_path_factory.mktemp("finished") / "o"
    first = subprocess.run(
        up_command(out, "--no-label-ui", "--train-args=--epochs 2"), capture_output=True, text=True, timeout=300
    )
    assert first.returncode == 0, first.stderr[-2000:]
    summary = json.loads((out / "trainer" / "summary.json").read_text())
    assert (summary["status"], summary["epochs_done"], summary["n_labels"]) == ("finished", 2, 2)
    return out


def copy_of(finished: Path, tmp_path: Path) -> Path:
    """A copy of the finished stack's OUT (its database, tokens, trainer folder and logs), stopped as
    it was: copy2 keeps the secrets' 0600."""
    out = tmp_path / "o"
    shutil.copytree(finished, out)
    return out


def cmdlines() -> list[bytes]:
    lines = []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            with contextlib.suppress(OSError):  # gone, or not ours to read
                lines.append(Path(f"/proc/{pid}/cmdline").read_bytes())
    return lines


def test_a_finished_stack_resumed_with_more_epochs_has_them_labelled_by_its_teacher(finished_stack, tmp_path):
    """The teacher starts while the run is still finished, before the trainer reopens it: it must
    start again and label the added epochs' session (it used to end at once, and the run waited)."""
    out = copy_of(finished_stack, tmp_path)  # finished at epoch 2, its session labelled
    more = subprocess.run(
        [*up_command(out, "--no-label-ui"), "--train-args", "--epochs 4"], capture_output=True, text=True, timeout=300
    )
    assert more.returncode == 0, more.stderr[-2000:]
    summary = json.loads((out / "trainer" / "summary.json").read_text())
    assert (summary["status"], summary["epochs_done"], summary["n_labels"]) == ("finished", 4, 4)  # and at 4


def test_tokens_starting_with_a_dash_stay_out_of_argv_logs_and_open_files(tmp_path):
    tokens = {"operator": "-op" + "o" * 40, "trainer": "-tr" + "t" * 40, "labeler": "--lb" + "l" * 40}
    (tmp_path / "tokens.json").write_text(json.dumps({"tokens": tokens}))  # a saved stack, reused as is
    proc = subprocess.Popen(up_command(tmp_path, SHORT_RUN), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    seen_children: set[str] = set()
    leaked: list[bytes] = []
    while proc.poll() is None:  # watch every process's command line while the stack runs
        seen_children |= set(children(tmp_path))
        leaked += [c for c in cmdlines() if any(t.encode() in c for t in tokens.values())]
        time.sleep(0.2)
    output = proc.stdout.read().decode()
    assert proc.returncode == 0, output[-3000:]
    assert seen_children >= {"service", "trainer", "teacher", "labeling_ui"}
    assert leaked == []
    for log in (tmp_path / "logs").iterdir():
        text = log.read_text(errors="replace")
        assert not [r for r, t in tokens.items() if t in text], f"a token is in {log.name}"
    for secret in (tmp_path / "tokens.json", tmp_path / "info.json"):
        assert secret.stat().st_mode & 0o777 == 0o600, secret
    meta = json.loads((tmp_path / "info.json").read_text())
    assert meta["tokens"] == tokens
    summary = json.loads((tmp_path / "trainer" / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["n_labels"] == summary["config"]["total_queries"]


def test_parts_killed_or_terminated_mid_run_are_restarted_and_the_run_finishes(tmp_path):
    """kill -9 of the teacher and the labeling UI, and SIGTERM of the trainer (which checkpoints and
    exits 0, "interrupted": not the end of the run)."""
    proc = subprocess.Popen(
        up_command(tmp_path, "--teacher-rate", "2", SHORT_RUN), stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    killed: dict[str, int] = {}
    try:
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline and len(killed) < 3:
            info = tmp_path / "info.json"
            if info.exists() and not killed:
                meta = json.loads(info.read_text())
                with CollieClient(meta["api"], meta["tokens"]["operator"]) as client:
                    run = client.run(meta["run_id"])
                if 0 < run.n_labels < run.n_total:  # mid-run: some labels given, more to come
                    for name, sig in (
                        ("teacher", signal.SIGKILL),
                        ("labeling_ui", signal.SIGKILL),
                        ("trainer", signal.SIGTERM),
                    ):
                        killed[name] = children(tmp_path)[name]
                        os.kill(killed[name], sig)
            time.sleep(0.1)
        assert proc.wait(timeout=300) == 0, proc.stdout.read().decode()[-3000:]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert set(killed) == {"teacher", "labeling_ui", "trainer"}
    now = children(tmp_path)
    assert all(now[name] != pid for name, pid in killed.items())  # each was started again
    up_log = (tmp_path / "logs" / "up.log").read_text()
    assert "teacher exited with signal 9; restarting" in up_log
    assert "labeling_ui exited with signal 9; restarting" in up_log
    assert "trainer exited with code 0 (interrupted); restarting" in up_log
    summary = json.loads((tmp_path / "trainer" / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["n_labels"] == summary["config"]["total_queries"]


def test_a_killed_service_comes_back_on_the_same_address_and_the_run_finishes(tmp_path):
    """`collie up` holds the service's listening socket: a restarted service serves it again, and
    the others' requests wait in its queue instead of being refused."""
    proc = subprocess.Popen(
        up_command(tmp_path, "--teacher-rate", "2", SHORT_RUN), stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    killed = None
    try:
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline and killed is None:
            info = tmp_path / "info.json"
            if info.exists():
                meta = json.loads(info.read_text())
                with CollieClient(meta["api"], meta["tokens"]["operator"]) as client:
                    run = client.run(meta["run_id"])
                if 0 < run.n_labels < run.n_total:
                    killed = children(tmp_path)["service"]
                    os.kill(killed, signal.SIGKILL)
            time.sleep(0.1)
        assert proc.wait(timeout=300) == 0, proc.stdout.read().decode()[-3000:]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert killed is not None and children(tmp_path)["service"] != killed
    assert "service exited with signal 9; restarting" in (tmp_path / "logs" / "up.log").read_text()
    summary = json.loads((tmp_path / "trainer" / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["n_labels"] == summary["config"]["total_queries"]


def test_a_service_port_in_use_is_an_error_naming_it(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        cmd = [*up_command(tmp_path / "stack"), "--info-json", str(tmp_path / "info" / "deeper" / "info.json")]
        cmd[cmd.index("--port") + 1] = str(port)
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2  # a refusal, as `collie serve` says it (was 1)
    assert proc.stderr.strip().splitlines()[-1] == (
        f"collie up: error: cannot listen on 127.0.0.1:{port} for the service: Address already in use "
        "(--port 0 takes any free port)"
    )
    assert not (tmp_path / "stack").exists()  # was left holding tokens.json, up.lock and logs/
    assert not (tmp_path / "info").exists()  # the folders made for --info-json go too


def test_a_run_folder_whose_database_is_gone_is_one_error_not_a_restart_loop(finished_stack, tmp_path):
    out = copy_of(finished_stack, tmp_path)
    (out / "collie.db").unlink()
    again = subprocess.run([*up_command(out), "--no-label-ui"], capture_output=True, text=True, timeout=300)
    assert again.returncode == 1 and "Traceback" not in again.stderr
    memo, db = out / "trainer" / "service_run.json", out / "collie.db"
    assert f"{memo} belongs to run 1, which the database ({db}) does not hold" in again.stderr
    assert "restarting" not in again.stderr
    assert not db.exists() and not list(out.glob("collie.db-*"))  # the empty one this start made is gone
    kept = copy_of(finished_stack, tmp_path / "kept")  # a database that was there stays, though it lacks the run
    with contextlib.closing(sqlite3.connect(kept / "collie.db")) as held:
        held.execute("UPDATE runs SET id = 7")  # another run than OUT/trainer's
        held.commit()
    refused = subprocess.run([*up_command(kept), "--no-label-ui"], capture_output=True, text=True, timeout=300)
    assert refused.returncode == 1 and "belongs to run 1" in refused.stderr and (kept / "collie.db").exists()


def test_a_part_that_keeps_dying_ends_the_stack_naming_it(tmp_path):
    proc = subprocess.Popen(
        up_command(tmp_path, "--no-label-ui", "--teacher-rate", "1", "--max-restarts", "1"),  # the teacher's end only
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    killed: set[int] = set()
    try:
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline:
            pid = children(tmp_path).get("teacher")
            if pid is not None and pid not in killed:
                killed.add(pid)
                os.kill(pid, signal.SIGKILL)
            time.sleep(0.1)
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    err = proc.stderr.read().decode()
    assert code == 1 and len(killed) == 2, err[-2000:]
    assert "the teacher keeps exiting" in err
    assert "giving up" in (tmp_path / "logs" / "up.log").read_text()


def test_a_part_that_refuses_to_run_ends_the_stack_at_once_saying_why(finished_stack, tmp_path):
    """A damaged checkpoint (or a revoked token) is refused the same way at every start: after one
    retry the stack ends with the trainer's own words, not six starts and "see the logs"."""
    out = copy_of(finished_stack, tmp_path)  # finished at epoch 2
    checkpoint = out / "trainer" / "checkpoint.pt"
    checkpoint.write_bytes(checkpoint.read_bytes()[:100])
    again = subprocess.run(
        up_command(out, "--no-label-ui", "--train-args=--epochs 4"), capture_output=True, text=True, timeout=300
    )
    assert again.returncode == 1 and "Traceback" not in again.stderr
    assert "collie up: error: the trainer refused to run again (code 2: collie train: error: " in again.stderr
    assert "checkpoint.pt" in again.stderr.splitlines()[-1]  # what it refused, in the error line itself
    log = (out / "logs" / "up.log").read_text()
    assert log.count("started trainer") == 3  # the first stack's, then one start and one retry


def alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"  # a zombie has ended
    except (OSError, IndexError):
        return False


def started_stack(out: Path) -> tuple[subprocess.Popen, dict[str, int]]:
    """A `collie up` whose service, teacher and labeling UI run and whose trainer is past its first
    epoch (its signal handlers in place; a long run keeps it going however slow the machine)."""
    proc = subprocess.Popen(
        up_command(out, "--teacher-rate", "0.2", "--train-args=--epochs 100000"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 180

    def check() -> None:
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(proc.communicate()[1].decode()[-2000:])
        time.sleep(0.1)

    while not ((out / "info.json").exists() and len(children(out)) == 4):
        check()
    meta = json.loads((out / "info.json").read_text())
    with CollieClient(meta["api"], meta["tokens"]["operator"]) as client:
        while client.run(meta["run_id"]).epoch < 1:
            check()
    return proc, children(out)


def test_a_second_stack_on_one_out_is_refused_and_a_killed_stack_takes_its_parts_along(tmp_path):
    proc, parts = started_stack(tmp_path)
    try:
        second = subprocess.run(up_command(tmp_path), capture_output=True, text=True, timeout=60)
        assert second.returncode == 2 and "Traceback" not in second.stderr
        assert (
            f"another collie up runs on --out {tmp_path} (collie up {proc.pid}, service {parts['service']}"
            in second.stderr
        )
        proc.kill()  # SIGKILL: no handler runs in collie up; its parts get SIGTERM from the kernel
        proc.wait()
        deadline = time.monotonic() + 60
        while any(alive(pid) for pid in parts.values()) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not [name for name, pid in parts.items() if alive(pid)]
    finally:
        for pid in parts.values():
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    summary = json.loads((tmp_path / "trainer" / "summary.json").read_text())
    assert summary["status"] == "interrupted"  # the trainer's SIGTERM path: checkpointed, resumable


def test_a_stack_that_crashed_before_its_first_checkpoint_resumes_its_run_not_a_new_one(tmp_path):
    """Every part SIGKILLed (a crash, the OOM killer) before the trainer wrote a checkpoint: the same
    command continues the run the service holds, its labels kept, instead of starting run 2."""
    proc = subprocess.Popen(
        up_command(tmp_path, "--train-args=--epochs 100000 --checkpoint-every 100000"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        while not ((tmp_path / "info.json").exists() and len(children(tmp_path)) == 4):
            assert proc.poll() is None, proc.communicate()[1].decode()[-2000:]
            time.sleep(0.1)
        meta = json.loads((tmp_path / "info.json").read_text())
        with CollieClient(meta["api"], meta["tokens"]["operator"]) as client:
            deadline = time.monotonic() + 180
            while client.run(meta["run_id"]).n_labels < 2:  # the first session (epoch 2) labelled
                assert time.monotonic() < deadline and proc.poll() is None
                time.sleep(0.2)
        proc.send_signal(signal.SIGSTOP)  # held first: it restarts no part while they are killed
        crashed = children(tmp_path)
        for pid in crashed.values():
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        proc.kill()
        proc.wait()
        deadline = time.monotonic() + 60  # gone, and with them their hold on the stack's lock
        while any(alive(pid) for pid in crashed.values()) and time.monotonic() < deadline:
            time.sleep(0.2)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not (tmp_path / "trainer" / "checkpoint.pt").exists()
    again = subprocess.run(  # its labeling UI has no part in what is checked here
        up_command(tmp_path, "--no-label-ui", "--train-args=--epochs 4"), capture_output=True, text=True, timeout=300
    )
    assert again.returncode == 0, again.stderr[-2000:]
    assert f"collie up: run {meta['run_id']} " in again.stdout
    assert "  label     " not in again.stdout  # the oracle labels: no link, no hint
    with contextlib.closing(sqlite3.connect(tmp_path / "collie.db")) as db:
        assert db.execute("SELECT id, status FROM runs").fetchall() == [(meta["run_id"], "finished")]  # no run 2
    summary = json.loads((tmp_path / "trainer" / "summary.json").read_text())
    assert (summary["status"], summary["n_labels"]) == ("finished", 4)  # the kept session's and epoch 4's


def test_a_closed_terminal_stops_the_stack_like_ctrl_c(tmp_path):
    proc, parts = started_stack(tmp_path)
    try:
        proc.send_signal(signal.SIGHUP)
        assert proc.wait(timeout=120) == 130
        assert not [name for name, pid in parts.items() if alive(pid)]
        said = proc.stdout.read().decode()  # type: ignore[union-attr]
        kept = tmp_path / "trainer"  # the trainer's final checkpoint, and how to go on (was: "stopping…" alone)
        assert f"collie up: stopped; the trainer's checkpoint is in {kept}: the same command goes on from it" in said
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "stopped" in (tmp_path / "logs" / "up.log").read_text()
