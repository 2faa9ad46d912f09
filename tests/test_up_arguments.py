"""`collie up` refuses what cannot work before it starts anything, names a failing part's own
error, and leaves a start that never gets ready when asked to stop."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from small_disk import fill, small_disk
from unprivileged import as_nobody, closed_folder

from collie.child_log import last_error
from collie.up import Stopped, wait_for, what_runs


def up(tmp_path: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "collie.cli", "up", "--no-label-ui", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=tmp_path)


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--port", "-1"], "argument --port: -1 is not a port"),
        (["--ui-port", "99999"], "argument --ui-port: 99999 is not a port"),
        (["--host", "example.org"], "argument --host: 'example.org' is not an IPv4 address"),
        (["--host", "203.0.113.250"], "--host 203.0.113.250 is not an address of this machine (Cannot assign"),
        (["--out", "afile"], "--out afile is a file"),
        (["--info-json", "."], "--info-json . is a folder"),
        (["--train-args=--out elsewhere --epochs 2"], "--train-args may not set --out"),
        (["--train-args", "--api=http://x"], "--train-args may not set --api"),  # a value that is one flag
        (["--teacher-rate", "-1", "--teacher", "oracle"], "--teacher-rate must be > 0"),
        (["--out", "/proc/nope"], "cannot create --out /proc/nope: No such file or directory"),
        (["--info-json", "afile/info.json"], "cannot create the folder of --info-json afile: File exists"),
        (["--train-args", "--epochs '3"], '--train-args "--epochs \'3": No closing quotation'),
        # the trainer's own refusals, asked before anything starts (was: the stack started, made OUT, then failed)
        (["--env", "pointt"], "collie train would refuse the run: unknown env 'pointt'; valid: point, ant,"),
        (["--task", "nort"], "collie train would refuse the run: unknown task 'nort'; valid tasks: north,"),
        (["--method", "colie"], "collie train would refuse the run: unknown method 'colie'; valid: collie,"),
        (["--train-args", "--bogus 3"], "collie train would refuse the run: unrecognized arguments: --bogus 3"),
        (["--train-args", "--epochs -3"], "collie train would refuse the run: --epochs must be ≥ 1, got -3"),
        (["--noise-band", "-1"], "collie train would refuse the run: --noise-band must be ≥ 0, got -1.0"),
        (  # was: refused only once the trainer built its nets, after the stack had started and made OUT
            ["--env", "humanoid", "--method", "lsd"],
            "collie train would refuse the run: LSD's Lipschitz φ reads state vectors, and humanoid observes",
        ),
    ],
)
def test_bad_arguments_are_refused_before_anything_starts(tmp_path: Path, args: list[str], said: str) -> None:
    (tmp_path / "afile").write_text("not a folder")
    proc = up(tmp_path, *args)
    assert proc.returncode == 2 and said in proc.stderr and "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # nothing was started or written


def test_a_weak_token_from_the_environment_is_refused_before_anything_starts(tmp_path: Path) -> None:
    env = {**os.environ, "COLLIE_OPERATOR_TOKEN": "change-me-operator-please"}
    command = [sys.executable, "-m", "collie.cli", "up", "--no-label-ui", "--out", str(tmp_path / "o")]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "collie up: error: COLLIE_OPERATOR_TOKEN is a placeholder (it holds 'change-me')" in proc.stderr
    assert "please" not in proc.stderr and not (tmp_path / "o").exists()


def test_the_labs_database_without_the_labs_tokens_is_refused(tmp_path: Path) -> None:
    env = {**os.environ, "COLLIE_DATABASE_URL": f"sqlite:///{tmp_path / 'lab.db'}", "COLLIE_OPERATOR_TOKEN": "o" * 20}
    command = [sys.executable, "-m", "collie.cli", "up", "--no-label-ui", "--out", str(tmp_path / "o")]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "give its tokens in COLLIE_TRAINER_TOKEN, COLLIE_LABELER_TOKEN (new ones would replace" in proc.stderr
    assert not (tmp_path / "lab.db").exists()


def test_a_resumed_stack_on_the_labs_database_takes_the_labs_tokens_not_its_older_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Was: a resumed stack put OUT/tokens.json's tokens back on the lab's database, replacing the
    ones the lab had rotated to since (every labeler locked out, nothing said), and with no
    COLLIE_<ROLE>_TOKEN it started on them as well."""
    from collie.up import stack_tokens

    out = tmp_path / "o"
    out.mkdir()
    older = {"operator": "o" * 32, "trainer": "t" * 32, "labeler": "l" * 32}
    (out / "tokens.json").write_text(json.dumps({"tokens": older}))
    env = {**os.environ, "COLLIE_DATABASE_URL": f"sqlite:///{tmp_path / 'lab.db'}", "COLLIE_OPERATOR_TOKEN": "p" * 20}
    command = [sys.executable, "-m", "collie.cli", "up", "--no-label-ui", "--out", str(out)]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert (
        f"give its tokens in COLLIE_TRAINER_TOKEN, COLLIE_LABELER_TOKEN (new ones, or the older ones in "
        f"{out / 'tokens.json'}, would replace the tokens everyone else uses there)"
    ) in proc.stderr
    assert not (tmp_path / "lab.db").exists()
    rotated = {"operator": "p" * 32, "trainer": "r" * 32, "labeler": "m" * 32}
    for role, token in rotated.items():
        monkeypatch.setenv(f"COLLIE_{role.upper()}_TOKEN", token)
    assert stack_tokens(out / "tokens.json", lab=True) == rotated
    assert stack_tokens(out / "tokens.json", lab=False) == older  # its own database: the links handed out stay


def test_another_stacks_database_without_its_tokens_is_refused(tmp_path: Path) -> None:
    """New random tokens would replace those of every link handed out for that database."""
    with sqlite3.connect(tmp_path / "old.db") as conn:
        conn.execute("CREATE TABLE principals (id INTEGER)")
    proc = up(tmp_path, "--db", "old.db", "--port", "0", "--out", "new")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "--db old.db holds a database already, but new has no tokens.json: give its tokens in" in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.db"]  # nothing was started or written


def test_a_part_that_fails_at_start_is_named_with_its_own_error(tmp_path: Path) -> None:
    """A refusal only the started trainer finds (its flags read well: `collie up` asked beforehand).
    No CUDA device is visible to the stack, on any machine."""
    command = [sys.executable, "-m", "collie.cli", "up", "--no-label-ui", "--train-args", "--device cuda"]
    command += ["--port", "0", "--out", str(tmp_path / "o")]
    hidden = {**os.environ, "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run(command, capture_output=True, text=True, timeout=120, cwd=tmp_path, env=hidden)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    said = "the trainer exited with code 2 before it was ready: collie train: error: --device cuda: torch sees no CUDA"
    assert said in proc.stderr


def test_a_service_that_cannot_open_its_database_is_named_with_the_reason(tmp_path: Path) -> None:
    (tmp_path / "notes.db").write_text("not a database")
    proc = up(tmp_path, "--db", "notes.db", "--port", "0", "--out", "o")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "the service exited with code 1: collie serve: error: cannot open the database" in proc.stderr
    assert "notes.db: file is not a database" in proc.stderr


def test_waiting_for_a_part_ends_when_asked_to_stop(tmp_path: Path) -> None:
    never = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    stopping = {"flag": False}
    threading.Timer(0.5, lambda: stopping.update(flag=True)).start()
    try:
        with pytest.raises(Stopped):
            wait_for(tmp_path / "never.json", never, "the labeling UI", timeout_s=30, stopping=stopping)
    finally:
        never.kill()
        never.wait()


def test_the_last_error_line_of_a_log(tmp_path: Path) -> None:
    log = tmp_path / "part.log"
    log.write_text("starting\nTraceback (most recent call last):\n  ...\nOverflowError: bind(): port\n\ndone\n")
    assert last_error(log) == "OverflowError: bind(): port"
    log.write_text(
        "Traceback (most recent call last):\n  ...\nsqlalchemy.exc.OperationalError: (sqlite3.OperationalError) "
        "file is not a database\n(Background on this error at: https://sqlalche.me/e/21/e3q8)\n"
    )
    assert last_error(log).startswith("sqlalchemy.exc.OperationalError: (sqlite3.OperationalError) file is not")
    log.write_text("only this\n")
    assert last_error(log) == "only this" and last_error(tmp_path / "missing.log") == ""


def test_a_silent_log_on_a_full_disk_is_put_down_to_the_disk(tmp_path: Path) -> None:
    """A part that could not write its own words (`collie up`: "the service exited with code 1",
    nothing more, on a disk with 40 KB free) is said to have a full disk under its log."""
    with small_disk(tmp_path / "disk") as disk:
        (disk / "service.log").touch()
        assert last_error(disk / "service.log") == ""  # 1 MB free, nearly all: not full
        fill(disk)
        said = last_error(disk / "service.log")
        assert said == f"nothing in its log: the disk under {disk} is full (0 KB free)", said
        (disk / "filler").unlink()
        (disk / "service.log").write_text("collie serve: error: its disk is full\n")  # its own words, when it could
        assert last_error(disk / "service.log") == "collie serve: error: its disk is full"


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["serve", "--port", "-1"], "argument --port: -1 is not a port"),
        (["serve", "--log-level", "bogus"], "argument --log-level: invalid choice"),
        (["label-ui", "--api", "http://127.0.0.1:1", "--port", "70000"], "argument --port: 70000 is not a port"),
        (["label-ui", "--api", "notaurl"], "argument --api: 'notaurl' is not an http:// or https:// URL"),
        (["teacher", "--api", "127.0.0.1:8000", "--run", "1"], "is not an http:// or https:// URL"),
    ],
)
def test_the_other_commands_refuse_bad_ports_and_urls_at_once(tmp_path: Path, args: list[str], said: str) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "collie.cli", *args], capture_output=True, text=True, timeout=60, cwd=tmp_path
    )
    assert proc.returncode == 2 and said in proc.stderr and "Traceback" not in proc.stderr


def test_a_task_file_run_is_named_by_its_task_not_the_file(tmp_path: Path) -> None:
    import argparse

    from collie.up import add_arguments, checked

    spec = tmp_path / "my_task.toml"
    spec.write_text(
        'name = "charger"\ndescription = "reach the charger"\n'
        '[[regions]]\nkind = "disc"\ndesirability = "good"\ncentre = [5.0, 5.0]\nradius = 2.0\n'
    )
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert checked(parser.parse_args(["--task-file", str(spec)])) == Path("runs/up-point-charger")  # as collie train


def test_a_stack_without_a_task_runs_its_envs_own() -> None:
    import argparse

    from collie.up import add_arguments, checked, task_flags

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--env", "half_cheetah"])
    assert checked(args) == Path("runs/up-half_cheetah-right") and task_flags(args) == ["--task", "right"]


@pytest.mark.parametrize("mode", [0o555, 0o000])  # may not write there; may not even look inside
def test_out_in_a_folder_this_user_may_not_write_or_enter_is_one_line(mode: int) -> None:
    from collie.cli import main

    with closed_folder(mode) as closed:
        code, err = as_nobody(
            lambda: main(["up", "--no-label-ui", "--out", str(closed / "run")]), preload=("collie.up",)
        )
        assert code == 2 and "collie up: error:" in err and "Traceback" not in err, err
        assert f"{closed / 'run'}" in err and "ermission denied" in err, err


def test_a_refusal_names_the_paths_it_has_and_no_none() -> None:
    from collie.cli import refusal_line

    assert refusal_line(PermissionError(13, "Permission denied")) == "permission denied"  # binding port 80
    assert refusal_line(PermissionError(13, "Permission denied", "/a")) == "permission denied: /a"
    assert refusal_line(PermissionError(13, "Permission denied", "/a", None, "/b")) == "permission denied: /a → /b"
    assert refusal_line(PermissionError("not allowed")) == "not allowed"


def test_flags_a_resumed_run_ignores_are_named_seed_included_and_only_those_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from collie.up import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    stored = tmp_path / "config.json"
    stored.write_text(json.dumps({"env": "point", "task": "north", "method": "collie", "preset": "smoke", "seed": 0}))
    args = parser.parse_args(["--seed", "5", "--task", "north"])
    assert what_runs(args, stored) == "point north collie (smoke)"
    said = capsys.readouterr().err
    # not "--preset cpu": that is the default, which nobody asked for (was named)
    assert "resuming a point north collie run; --seed 5 ignored (another --out starts a new run)\n" in said
    what_runs(parser.parse_args(["--seed", "0", "--env", "point"]), stored)
    assert capsys.readouterr().err == ""  # nothing given differs: nothing said
    what_runs(parser.parse_args(["--env", "ant", "--preset", "cpu"]), stored)
    assert "run; --env ant, --preset cpu ignored" in capsys.readouterr().err


def test_a_stack_whose_trainer_token_was_revoked_says_it_cannot_run_again(tmp_path: Path) -> None:
    """The service leaves a revoked role out of OUT/tokens.json; the next `collie up` on that --out
    was a KeyError traceback ('trainer')."""
    from collie.up import stack_tokens

    tokens = tmp_path / "tokens.json"
    tokens.write_text(json.dumps({"tokens": {"operator": "o" * 32, "labeler": "l" * 32}}))
    with pytest.raises(RuntimeError) as caught:
        stack_tokens(tokens, lab=False)
    assert str(caught.value) == (
        f"{tokens} holds no trainer token (revoked on the service: final); this stack cannot run again: "
        "start a new one in another --out"
    )


def test_a_stack_without_a_labeling_ui_or_a_teacher_says_how_labels_come(tmp_path: Path) -> None:
    """Was: no label link and no word, and then "waiting for labels" for good."""
    command = [sys.executable, "-m", "collie.cli", "up", "--no-label-ui", "--preset", "smoke", "--port", "0"]
    proc = subprocess.Popen([*command, "--out", str(tmp_path / "o")], stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        assert proc.stdout is not None
        printed = []
        for line in proc.stdout:
            printed.append(line)
            if line.startswith("  dashboard "):
                break
        label = [line for line in printed if line.startswith("  label     ")]
        assert len(label) == 1 and "no labeling UI here (--no-label-ui): `collie label-ui --api http://" in label[0]
        assert "--token TOKEN` with a labeler's token (dashboard → Labelers), or --teacher oracle" in label[0]
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=120)
    assert proc.returncode == 130  # Ctrl-C's


def test_a_refusal_for_a_stack_in_the_way_names_only_its_processes_that_run(tmp_path: Path) -> None:
    """Was: every pid OUT/children.json named, those a SIGKILL had ended too."""
    from collie.processes import hold_lock
    from collie.up import locked

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(gone.stdout)
    (tmp_path / "children.json").write_text(json.dumps({"up": dead, "children": {"service": os.getpid()}}))
    fd = hold_lock(tmp_path / "up.lock")  # the stack still holds OUT (here: this process)
    try:
        with pytest.raises(ValueError, match=rf"\(service {os.getpid()}\): stop it") as refused:
            locked(tmp_path)
        assert str(dead) not in str(refused.value)
        (tmp_path / "children.json").write_text(json.dumps({"up": dead, "children": {}}))
        with pytest.raises(ValueError, match=r"\(find them with `fuser -v .*up\.lock`\)"):
            locked(tmp_path)
    finally:
        os.close(fd)


def test_a_part_killed_before_it_was_ready_is_said_to_have_ended_by_a_signal(tmp_path: Path) -> None:
    """Was "exited with code -9", where the supervisor says "signal 9" of the same death."""
    killed = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    killed.kill()
    killed.wait()
    with pytest.raises(RuntimeError, match=r"^the trainer exited with signal 9 before it was ready$"):
        wait_for(tmp_path / "never.json", killed, "the trainer", timeout_s=30)


def test_a_zombie_is_no_running_process() -> None:
    """A child that ended but was not yet waited for keeps its pid: it runs no more."""
    from collie.processes import running

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while Path(f"/proc/{child.pid}/stat").read_text().rsplit(") ", 1)[1][:1] != "Z":
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert not running(child.pid) and running(os.getpid())
    child.wait()
    assert not running(child.pid) and not running(True) and not running(-1)
