"""The supervisor of `collie up`'s parts on a disk it cannot write (full): the parts still run."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from collie.supervisor import Supervisor


def test_a_children_file_that_cannot_be_written_is_a_warning_not_the_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "children.json").mkdir()  # renaming a file over a folder fails, as a write on a full disk does
    stack = Supervisor(tmp_path)
    try:
        proc = stack.start("helpful", lambda: ["--help"], dict(os.environ))
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert proc.returncode == 0
    finally:
        stack.stop()
    assert f"collie up: warning: cannot write {tmp_path / 'children.json'}: " in capsys.readouterr().err
    assert not (tmp_path / "children.json.partial").exists()


def test_a_part_whose_failure_no_restart_can_mend_ends_the_stack_at_its_first_exit(tmp_path: Path) -> None:
    """The trainer of a run that failed (diverged) would replay it to the same failure: no restart."""
    from collie.supervisor import ChildFailed

    stack = Supervisor(tmp_path)
    try:
        proc = stack.start("trainer", lambda: ["train", "--env", "nope"], dict(os.environ), fatal=lambda: "run failed")
        proc.wait(timeout=60)
        with pytest.raises(ChildFailed, match="the trainer's run failed"):
            stack.check()
    finally:
        stack.stop()
    assert "started trainer" in (tmp_path / "logs" / "up.log").read_text()
    assert (tmp_path / "logs" / "up.log").read_text().count("started trainer") == 1  # never restarted


def test_a_resumed_stack_given_no_rule_passes_none_to_its_trainer() -> None:
    """A default --task would contradict a run made with another (the trainer refuses it)."""
    import argparse

    from collie.up import add_arguments, run_task_flags, task_flags

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    bare, named = parser.parse_args([]), parser.parse_args(["--task", "range"])
    for args in (bare, named):
        args.task_flags = task_flags(args)
    assert run_task_flags(bare, resume=True) == [] and run_task_flags(bare, resume=False) == ["--task", "north"]
    assert run_task_flags(named, resume=True) == ["--task", "range"]


def _killed_and_checked(stack: Supervisor, name: str) -> None:
    """SIGKILL the part's current process and let the supervisor see it die (and plan a restart)."""
    proc = stack.proc(name)
    proc.kill()
    proc.wait(timeout=30)
    stack.check()


def _restarted(stack: Supervisor, name: str, before: int) -> None:
    deadline = time.monotonic() + 30
    while stack.proc(name).pid == before and time.monotonic() < deadline:
        time.sleep(0.1)
        stack.check()
    assert stack.proc(name).pid != before, "not restarted"


@pytest.mark.parametrize("progressing", [True, False])
def test_a_part_killed_again_and_again_is_restarted_while_it_makes_progress(tmp_path: Path, progressing: bool) -> None:
    """A trainer killed twice within `stable_s` ends the stack, unless its checkpoint moved between
    the kills: each start then got somewhere, and the next resumes from there."""
    from collie.supervisor import ChildFailed

    checkpoints = [0]
    stack = Supervisor(tmp_path, max_restarts=1, stable_s=600)
    serve = ["serve", "--port", "0", "--db", str(tmp_path / "c.db"), "--tokens-json", str(tmp_path / "t.json")]
    try:
        stack.start("service", lambda: serve, dict(os.environ), progress=lambda: checkpoints[0])
        first = stack.proc("service").pid
        _killed_and_checked(stack, "service")  # the first death: restarted
        _restarted(stack, "service", first)
        if progressing:
            checkpoints[0] += 1  # the restarted start checkpointed before it was killed
            second = stack.proc("service").pid
            _killed_and_checked(stack, "service")
            _restarted(stack, "service", second)
        else:
            with pytest.raises(ChildFailed, match="the service keeps exiting"):
                _killed_and_checked(stack, "service")
    finally:
        stack.stop()


def test_a_part_that_ended_early_is_not_restarted_once_its_work_is_over(tmp_path: Path) -> None:
    """The oracle teacher sees a run finished (and exits 0) before the trainer has written its last
    files and exited: the teacher is then done, not started again (was: restarted, and the log said
    it ended "before its work")."""
    over = False
    stack = Supervisor(tmp_path)
    try:
        proc = stack.start("teacher", lambda: ["--help"], dict(os.environ), lambda: over, again_after_s=1.0)
        proc.wait(timeout=60)
        stack.check()  # its work is not over yet: a restart is planned
        over = True  # the trainer finished within the delay
        time.sleep(1.2)
        stack.check()
        assert stack.finished("teacher") and stack.proc("teacher") is proc
    finally:
        stack.stop()
    log = (tmp_path / "logs" / "up.log").read_text()
    assert log.count("started teacher") == 1 and "teacher finished (exit 0)" in log


def test_a_part_that_keeps_ending_early_waits_at_most_four_times_its_delay(tmp_path: Path) -> None:
    """A resumed run's teacher ends at once (the run is finished) until the trainer reopens it: its
    waits double 1×, 2×, 4×, then stay at 4× (was: 8×, 16×, up to 30 s, so the first labels of a
    resumed run waited that long after the trainer was ready)."""
    stack = Supervisor(tmp_path)
    try:
        stack.start("teacher", lambda: ["--help"], dict(os.environ), lambda: False, again_after_s=0.1)
        deadline = time.monotonic() + 120
        log = tmp_path / "logs" / "up.log"
        while log.read_text().count("again in") < 6 and time.monotonic() < deadline:
            stack.proc("teacher").wait(timeout=60)
            stack.check()
            time.sleep(0.05)
    finally:
        stack.stop()
    delays = [float(d) for d in re.findall(r"again in ([0-9.]+) s", log.read_text())]
    assert delays[:6] == [0.1, 0.2, 0.4, 0.4, 0.4, 0.4], delays
    assert "teacher ended (exit 0): its run takes no work now (finished or stopping); again in" in log.read_text()


HOLDER = """
import sys
from trainer.memory_ledger import reserve
reserve("a run beside the stack", int(sys.argv[1]))
print("promised", flush=True)
sys.stdin.read()
"""


def test_a_trainer_refused_for_memory_runs_beside_it_hold_waits_for_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Exit 75 (trainer/memory_ledger.py) is no death: the trainer tries again until the run beside
    the stack has ended, however many tries that takes (was: restarted with the backoff of a crash,
    then given up after its restarts, within a minute)."""
    import numpy as np

    import collie.supervisor
    from trainer.config import make_config
    from trainer.envs.registry import make_env
    from trainer.memory_ledger import LEDGER_ENV
    from trainer.memory_plan import available_bytes, replay_fill_bytes

    monkeypatch.setattr(collie.supervisor, "WAIT_FOR_MEMORY_S", 0.5)
    cfg, env = make_config("smoke", "point"), make_env("point")
    free = available_bytes()
    assert free is not None
    each = replay_fill_bytes(
        1, cfg.episode_steps, env.obs_shape, np.dtype(env.obs_dtype), env.action_dim, env.nq, env.nv
    )
    held = int(0.55 * free / each)  # trajectories: fits alone, not beside the holder's promise as large
    sizes = ["--epochs", str(held // cfg.episodes_per_epoch + 1), "--replay-capacity", str(held * cfg.episode_steps)]
    ledger = tmp_path / "ledger"
    environ = {**os.environ, LEDGER_ENV: str(ledger)}
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(int(0.55 * free))],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        env=environ,
    )
    stack = Supervisor(tmp_path / "up", max_restarts=1)
    log = tmp_path / "up" / "logs" / "up.log"
    try:
        assert holder.stdout is not None and holder.stdout.readline() == b"promised\n"
        train = [
            "train",
            "--env",
            "point",
            "--preset",
            "smoke",
            "--no-progress",
            *sizes,
            "--out",
            str(tmp_path / "run"),
        ]
        stack.start("trainer", lambda: train, environ)

        def until(happened, what: str) -> None:
            deadline = time.monotonic() + 120
            while not happened():
                stack.check()  # ChildFailed here if the refusals were counted as deaths (max_restarts 1)
                assert time.monotonic() < deadline, f"{what}; up.log: {log.read_text()}"
                time.sleep(0.2)

        until(lambda: log.read_text().count("refused for memory other runs were promised") >= 3, "no third refusal")
        holder.kill()
        holder.wait()
        until(lambda: any(ledger.glob(f"{stack.proc('trainer').pid}.json")), "the trainer never started")
    finally:
        holder.kill()
        stack.stop()
    said = capsys.readouterr().err
    assert said.count("collie up: the trainer waits for memory (collie train: error: this machine has not enough") == 1
    assert "trying again every 0.5 s" in said
