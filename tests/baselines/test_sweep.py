"""`collie sweep`: finished runs are not rerun, interrupted ones resume, folders name their runs."""

import argparse
import json
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import asdict, replace
from pathlib import Path

import pytest
from paced_marks import PacedMarks

from trainer import sweep
from trainer.sweep import RunSpec, grid, run_all, run_one, train_command


def finished(folder, **summary):
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({"status": "finished", "safe_coverage": 1.0, **summary}))


def test_grid_names_folders_and_orders_seed_by_seed(tmp_path):
    specs = grid(tmp_path, "point", ["north", "range"], ["metra", "collie"], [0, 1], variant="additive")
    assert [s.seed for s in specs] == [0] * 4 + [1] * 4
    assert specs[0].out == str(tmp_path / "point-north-metra+additive-s0")


def test_finished_runs_are_skipped_and_interrupted_ones_resume(tmp_path, monkeypatch):
    done = RunSpec("point", "north", "metra", 0, str(tmp_path / "done"))
    finished(tmp_path / "done", safe_coverage=7.0)
    half = RunSpec("point", "north", "collie", 0, str(tmp_path / "half"), flags=("--epochs", "3"))
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "checkpoint.pt").write_bytes(b"")
    calls = []

    def fake_run(cmd, **kw):
        calls.append(cmd)
        (tmp_path / "half" / "summary.json").write_text(json.dumps({"status": "finished"}))
        return 0

    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: fake_run(cmd))
    results = {s.out: r for s, r in run_all([done, half], jobs=2)}
    assert results[done.out]["safe_coverage"] == 7.0
    assert len(calls) == 1 and calls[0][-1] == "--resume" and "--epochs" in calls[0]
    assert json.loads((tmp_path / "half" / "sweep_run.json").read_text())["method"] == "collie"
    assert "--resume" not in train_command(RunSpec("point", "north", "metra", 0, str(tmp_path / "new")))


def test_a_failed_run_is_reported_and_the_others_go_on(tmp_path, monkeypatch):
    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: 1)
    finished(tmp_path / "ok")
    specs = [
        RunSpec("point", "north", "metra", 0, str(tmp_path / "bad")),
        RunSpec("point", "north", "metra", 1, str(tmp_path / "ok")),
    ]
    out = {s.out: r for s, r in run_all(specs, jobs=1)}
    assert isinstance(out[specs[0].out], RuntimeError) and "see" in str(out[specs[0].out])
    assert out[specs[1].out]["status"] == "finished"
    with pytest.raises(RuntimeError):
        run_one(specs[0])


def test_a_run_stopped_by_a_signal_is_not_evaluated_and_a_stale_evaluation_is_redone(tmp_path, monkeypatch):
    spec = RunSpec("point", "north", "collie", 0, str(tmp_path / "run"), downstream=True)
    calls = []

    def stopped(cmd, **kw):  # `collie train` exits 0 after SIGINT, with a final checkpoint
        calls.append(cmd)
        (tmp_path / "run" / "summary.json").write_text(json.dumps({"status": "interrupted", "epochs_done": 658}))
        return 0

    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: stopped(cmd))
    with pytest.raises(RuntimeError, match=r"stopped before its last epoch .*'interrupted'.* rerun the sweep"):
        run_one(spec)
    assert len(calls) == 1 and "train" in calls[0]  # no downstream task on the unfinished policy

    finished(tmp_path / "done", epochs_done=2000)
    (tmp_path / "done" / "downstream.json").write_text(json.dumps({"zero_shot": {"mean": 1.0, "epoch": 658}}))
    assert not sweep.downstream_done(tmp_path / "done")  # from an earlier policy: computed again
    (tmp_path / "done" / "downstream.json").write_text(json.dumps({"zero_shot": {"mean": 1.0, "epoch": 2000}}))
    assert sweep.downstream_done(tmp_path / "done")


def test_collie_sweep_end_to_end_then_resume_skips(tmp_path):
    """From --first-seed 1, as a sweep split over machines (or continuing lost seeds) runs."""
    cmd = [
        sys.executable,
        "-m",
        "collie.cli",
        "sweep",
        "--tasks",
        "north",
        "--methods",
        "lsd",
        "--seeds",
        "1",
        "--first-seed",
        "1",
        "--preset",
        "smoke",
        "--out",
        str(tmp_path),
        "--jobs",
        "1",
        "--",
        "--epochs",
        "2",
    ]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    assert not (tmp_path / "point-north-lsd-s0").exists()  # --first-seed 1: seed 1 alone
    summary = tmp_path / "point-north-lsd-s1" / "summary.json"
    stamp = summary.stat().st_mtime_ns
    assert json.loads(summary.read_text())["epochs_done"] == 2
    assert "LSD" in (tmp_path / "report" / "report.md").read_text()
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0 and "1 already finished" in again.stdout
    assert summary.stat().st_mtime_ns == stamp
    assert "warning" not in again.stderr  # the same flags: nothing to say
    run = tmp_path / "point-north-lsd-s1"
    longer = subprocess.run([*cmd[:-1], "4"], capture_output=True, text=True, timeout=300)  # -- --epochs 4
    assert longer.returncode == 0, longer.stderr
    assert f"{run}: finished at 2 epochs; extended to 4 (resumed from its checkpoint)" in longer.stdout
    assert json.loads(summary.read_text())["epochs_done"] == 4
    assert "1 run, 0 already finished, 1 resumed from their checkpoints; engine" in longer.stdout
    epochs = [json.loads(line)["epoch"] for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert epochs == sorted(set(epochs)), epochs  # continued, not trained again from epoch 0
    stamp = summary.stat().st_mtime_ns
    other = subprocess.run([*cmd[:-1], "4", "--hidden", "32"], capture_output=True, text=True, timeout=300)
    assert other.returncode == 0 and summary.stat().st_mtime_ns == stamp  # not rerun, but said so:
    assert (
        f"warning: {run} finished with --preset smoke -- --epochs 4, not --preset smoke -- --epochs 4 --hidden 32 "
        "(--hidden 64, not 32); not rerun (remove it to rerun)"
    ) in other.stderr
    shorter = subprocess.run(cmd, capture_output=True, text=True, timeout=300)  # -- --epochs 2
    assert shorter.returncode == 0 and summary.stat().st_mtime_ns == stamp
    assert "(--epochs 4, not 2); not rerun (remove it to rerun)" in shorter.stderr


@pytest.mark.parametrize(
    ("given", "message"),
    [
        (["--tasks", "nort", "--preset", "smok"], "unknown task(s) nort; valid: north, right, range,"),
        (["--preset", "smok"], "unknown --preset 'smok'; valid: paper, cpu, smoke"),
        (["--env", "pont"], "unknown --env 'pont'; valid: point, ant,"),
        (["--tasks", "hazard"], "task hazard on --env point: task 'hazard' is not defined for env 'point'"),
        (["--tasks", "north,,range"], "--tasks 'north,,range': entry 2 of 3 is empty"),
        (["--methods", "metra,"], "--methods 'metra,': entry 2 of 2 is empty"),
        (["--tasks", ""], "--tasks '': entry 1 of 1 is empty"),  # was: the default task grid, run for hours
        (["--methods", ""], "--methods '': entry 1 of 1 is empty"),
        (["--downstream-flags", "'oops"], '--downstream-flags "\'oops": No closing quotation'),
        (["--out", "{file}"], "--out {file} is a file, not a folder"),
        (  # was: every run trained first, then each downstream task failed
            ["--downstream", "--downstream-flags", "--bogus 1"],
            "--downstream-flags '--bogus 1': python -m trainer.downstream would refuse them: unrecognized arguments",
        ),
        (
            ["--downstream", "--downstream-flags", "--trajectories 0"],
            "--downstream-flags '--trajectories 0': python -m trainer.downstream would refuse them: --trajectories",
        ),
        (["--jobs", "0"], "--jobs must be ≥ 1"),
        (
            ["--methods", "lsd", "--tasks", "north", "--", "--epochs", "-5"],
            "collie train would refuse lsd on north (--epochs -5): --epochs must be ≥ 1, got -5",
        ),
        (
            ["--methods", "lsd", "--", "--bogus"],
            "collie train would refuse lsd on north (--bogus): unrecognized arguments",
        ),
        (["--tasks", "charger"], "unknown task(s) charger; valid: north, right, range,"),
        (["--task-file", "{file}"], "--task-file {file}: task file {file}: expected a .toml, .json or .py file, got"),
        (["--task-file", "{file}.toml"], "--task-file {file}.toml: task file {file}.toml: no such file"),
        (["--methods", "lsd", "--", "--task-file", "{file}"], "--task-file goes before --: `collie sweep --task-file"),
        (  # was: the run written to /tmp/x, then "FAILED …: stopped before its last epoch (status None)"
            ["--methods", "lsd", "--", "--epochs", "1", "--out=/tmp/x"],
            "flags after -- may not set --out=/tmp/x: collie sweep sets them for each run (--out: give collie sweep",
        ),
        (  # was: seed 3 run in a folder named -s0
            ["--methods", "lsd", "--", "--seed=3", "--out", "/tmp/x"],
            "flags after -- may not set --seed=3, --out: collie sweep sets them for each run (--seed: give",
        ),
        (  # an abbreviation is no flag of collie train's (argparse would have taken it for --out)
            ["--methods", "lsd", "--", "--ou", "/tmp/x"],
            "collie train would refuse lsd on north (--ou /tmp/x): unrecognized arguments: --ou",
        ),
        (["--methods", "lsd", "--", "--threads", "2"], "flags after -- may not set --threads: "),
        (["--ray", "notanaddr"], "--ray 'notanaddr' is not a Ray address: auto, HOST:PORT of the head, or ray://"),
        (["--ray", "head:²"], "--ray 'head:²' is not a Ray address"),  # a digit to str.isdigit, no int: was a traceback
        (["--ray", "http://head:6379"], "--ray 'http://head:6379' is not a Ray address"),  # was: "no Ray head answers"
    ],
)
def test_bad_arguments_are_one_line_errors_before_any_run_starts(tmp_path, capsys, monkeypatch, given, message):
    from collie.cli import main

    launched = []  # a run that would start is recorded (and fails) instead of training
    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: launched.append(cmd) or 1)
    file = tmp_path / "a-file"
    file.write_text("")
    out = ["--out", str(tmp_path / "runs")] if "--out" not in given else []
    argv = ["sweep", "--seeds", "1", *out, *[g.format(file=file) for g in given]]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie sweep: error: {message.format(file=file)}") and len(err.splitlines()) == 1, err
    assert launched == [] and not (tmp_path / "runs").exists()  # nothing launched, no empty report


def test_a_bad_train_flag_is_refused_when_every_run_has_finished_too(tmp_path, capsys, monkeypatch):
    """Was: "1 runs, 1 already finished", exit 0: the typo went unnoticed until a run was left to do."""
    from collie.cli import main

    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: pytest.fail(f"launched {cmd}"))
    finished(tmp_path / "runs" / "point-north-lsd-s0")
    argv = ["sweep", "--seeds", "1", "--methods", "lsd", "--tasks", "north", "--out", str(tmp_path / "runs")]
    assert main([*argv, "--", "--epohcs", "3"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("collie sweep: error: collie train would refuse lsd on north (--epohcs 3): unrecognized")


def test_a_ray_address_where_no_head_answers_is_a_one_line_error(tmp_path):
    import socket

    with socket.socket() as probe:  # a port nothing listens on: bound, then closed
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    cmd = [sys.executable, "-m", "collie.cli", "sweep", "--ray", f"127.0.0.1:{port}", "--tasks", "north"]
    cmd += ["--methods", "metra", "--seeds", "1", "--preset", "smoke", "--out", str(tmp_path / "sw"), "--no-report"]
    # ray.init alone retries forever: the timeout fails that; the probe's refusal is immediate, and
    # the rest of the time is the interpreter and its imports (no wall-clock bound on those)
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert f"collie sweep: error: --ray 127.0.0.1:{port}: no Ray head answers at that address" in done.stderr
    assert done.stdout == "" and not (tmp_path / "sw").exists()  # was: "1 run, …; engine: ray …" and an empty --out


def test_variant_names_are_letters_digits_and_underscores_and_an_underscore_alone_is_one(tmp_path, capsys):
    from collie.cli import main

    finished(tmp_path / "point-north-metra+_-s0")  # so the accepted sweep has nothing to train
    argv = ["sweep", "--tasks", "north", "--methods", "metra", "--seeds", "1", "--out", str(tmp_path), "--no-report"]
    assert main([*argv, "--variant", "_"]) == 0
    assert main([*argv, "--variant", "a-b"]) == 2
    assert "collie sweep: error: --variant 'a-b': letters, digits and _ only" in capsys.readouterr().err


def test_help_shows_the_full_grid_and_a_train_flag_before_the_separator_gets_a_hint(capsys):
    from collie.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["sweep", "--help"])
    assert exit_.value.code == 0
    shown = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    assert (
        "(default: point)" in shown
        and "(default: north,range,hole_north; half_cheetah: right,not_flip; car: hazard)" in shown
        and "(default: cpu)" in shown
    )
    assert "A bare `collie sweep` runs the full grid" in shown and "63 runs" in shown
    with pytest.raises(SystemExit) as exit_:
        main(["sweep", "--epochs", "2"])
    assert exit_.value.code == 2
    assert "unrecognized arguments: --epochs; flags for every `collie train` go after --" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["archive", "--help"])
    assert "(default: ./results)" in " ".join(capsys.readouterr().out.split())


def sweep_command(out, *more: str) -> list[str]:
    return [sys.executable, "-m", "collie.cli", "sweep", "--preset", "smoke", "--out", str(out), "--no-report", *more]


def test_a_name_given_twice_is_one_run(tmp_path):
    done = subprocess.run(
        sweep_command(
            tmp_path, "--tasks", "north,north", "--methods", "lsd,lsd", "--seeds", "1", "--", "--epochs", "1"
        ),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0 and done.stdout.startswith("1 run,"), done.stdout + done.stderr


def test_an_interrupted_sweep_stops_its_run_with_a_checkpoint_and_starts_no_other(tmp_path):
    more = (
        "--tasks",
        "north",
        "--methods",
        "lsd",
        "--seeds",
        "3",
        "--jobs",
        "1",
        "--",
        "--epochs",
        "100000",
        "--eval-every",
        "1",
    )
    proc = subprocess.Popen(sweep_command(tmp_path, *more), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = tmp_path / "point-north-lsd-s0"
    try:
        deadline = time.monotonic() + 180
        metrics = first / "metrics.jsonl"
        while not (metrics.exists() and len(metrics.read_text().splitlines()) >= 2):  # epoch 1: in the loop
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail(proc.communicate()[1][-3000:])
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)  # to the sweep alone, as a terminal's Ctrl-C now reaches it
        proc.send_signal(signal.SIGINT)  # twice: the trainer still gets one SIGTERM, and checkpoints
        _, err = proc.communicate(timeout=240)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "collie sweep: interrupted; 1 run(s) stopped, 2 not started; rerun the same command to resume" in err
    assert re.findall(r"\| (\d)/3 \[", err)[-1] == "0", err  # the progress bar counts no run as done
    assert json.loads((first / "summary.json").read_text())["status"] == "interrupted"
    assert (first / "checkpoint.pt").exists()
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == [first.name]  # seeds 1 and 2 never began


def test_a_sweep_interrupted_while_its_run_starts_reports_it_stopped_not_failed(tmp_path):
    """Was: "FAILED …: failed (130)" beside "0 run(s) stopped", and the progress bar counted it done."""
    marks = PacedMarks(tmp_path)
    more = ("--tasks", "north", "--methods", "lsd", "--seeds", "1", "--jobs", "1", "--", "--epochs", "100000")
    proc = subprocess.Popen(
        sweep_command(tmp_path / "sweep", *more),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=marks.env,
    )
    # the trainer's first mark (the sweep marks too): its imports next, seconds long
    marks.signal_at(proc, lambda m: m.pid != proc.pid and m.what == "python start", signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=240)
    finally:
        proc.kill()
        marks.release()
    assert marks.sent.is_set(), err[-3000:]
    assert proc.returncode == 130 and "FAILED" not in err, err[-3000:]
    assert "collie sweep: interrupted; 1 run(s) stopped, 0 not started; rerun the same command to resume" in err
    assert re.findall(r"\| (\d)/1 \[", err)[-1] == "0", err  # the progress bar counts no run as done


CHARGER = """\
name = "charger"
description = "Stay near the charger at (0, 0)."
[[regions]]
kind = "outside_disc"
desirability = "bad"
centre = [0, 0]
radius = 15
"""


def test_a_sweep_runs_a_task_from_a_file_given_by_a_relative_path(tmp_path):
    (tmp_path / "charger.toml").write_text(CHARGER)
    cmd = sweep_command("runs", "--task-file", "charger.toml", "--methods", "metra", "--seeds", "1", "--jobs", "1")
    done = subprocess.run([*cmd, "--", "--epochs", "1"], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.startswith("1 run,"), done.stdout + done.stderr
    run = tmp_path / "runs" / "point-charger-metra-s0"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["config"]["task"] == "charger"
    assert json.loads((run / "task.json").read_text())["definition"]["name"] == "charger"


def test_task_files_are_checked_before_any_run_starts(tmp_path, capsys, monkeypatch):
    from collie.cli import main

    launched = []
    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: launched.append(cmd) or 1)
    (tmp_path / "charger.toml").write_text(CHARGER)
    (tmp_path / "also.json").write_text(json.dumps({"name": "charger", "description": "d", "regions": []}))
    two = "from collie.tasks import Task, register_task\n"
    two += "".join(f"register_task('{n}')(lambda env: Task('{n}', 'd'))\n" for n in ("sw_a_test", "sw_b_test"))
    (tmp_path / "two.py").write_text(two)
    argv = ["sweep", "--methods", "metra", "--seeds", "1", "--out", str(tmp_path / "runs")]
    assert main([*argv, "--task-file", str(tmp_path / "charger.toml"), "--task-file", str(tmp_path / "also.json")]) == 2
    err = capsys.readouterr().err
    assert f"error: --task-file {tmp_path / 'also.json'} defines task 'charger', as --task-file " in err
    assert main([*argv, "--task-file", str(tmp_path / "two.py")]) == 2
    assert "registers sw_a_test, sw_b_test; a sweep takes one task per file" in capsys.readouterr().err
    assert main([*argv, "--task-file", str(tmp_path / "charger.toml"), "--tasks", "charger,nort"]) == 2
    assert "unknown task(s) nort;" in capsys.readouterr().err
    assert launched == [] and not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    ("env", "tasks"), [("point", "north,range,hole_north"), ("half_cheetah", "right,not_flip"), ("car", "hazard")]
)
def test_a_sweep_without_tasks_runs_the_envs_own(env, tasks):
    assert sweep.chosen_tasks(None, {}, env) == (tasks.split(","), None)


def test_a_task_file_joins_the_tasks_given_and_only_its_runs_read_it(tmp_path):
    (tmp_path / "charger.toml").write_text(CHARGER)
    parser = argparse.ArgumentParser()
    sweep.add_arguments(parser)
    args = parser.parse_args(["--tasks", "north", "--task-file", str(tmp_path / "charger.toml")])
    found, wrong = sweep.file_tasks(args.task_file, "point", 0)
    tasks, _ = sweep.chosen_tasks(args.tasks, found, "point")
    assert wrong is None and tasks == ["north", "charger"]
    specs = grid(tmp_path, "point", tasks, ["metra"], [0], found)
    assert "--task-file" not in sweep.train_argv(specs[0])
    assert sweep.train_argv(specs[1])[3:7] == ["charger", "--task-file", str(tmp_path / "charger.toml"), "--method"]
    assert sweep.train_flags_problem(specs) is None  # `collie train` takes both commands


def interrupted(spec: RunSpec, kept_in: str = "summary.json", status: str = "interrupted") -> None:
    """`spec.out` as the first sweep's `collie train` of `spec` leaves it when stopped (or `status`):
    its config (in summary.json, or config.json alone for one killed before its first summary), a
    checkpoint and the sweep's sweep_run.json."""
    folder = Path(spec.out)
    folder.mkdir(parents=True, exist_ok=True)
    config = sweep.intended_config(spec)  # what `collie train` made of the first sweep's command
    assert config is not None
    config.pop("rule", None)  # the digest of its task file's rule: task.json holds the rule itself
    saved = {"status": status, "config": config} if kept_in == "summary.json" else config
    (folder / kept_in).write_text(json.dumps(saved))
    (folder / "sweep_run.json").write_text(json.dumps(asdict(spec)))
    (folder / "checkpoint.pt").write_bytes(b"")


def test_a_rerun_with_other_train_flags_warns_of_each_interrupted_run_that_resumes_with_its_own(tmp_path, capsys):
    """Was: "4 runs, 0 already finished" alone; the resumed runs kept their flags, said only in their .log."""
    old = grid(tmp_path, "point", ["north"], ["metra", "lsd"], [0], flags=("--epochs", "4", "--hidden", "32"))
    for spec, kept_in in zip(old, ("summary.json", "config.json"), strict=True):  # lsd: killed before its summary
        interrupted(spec, kept_in)
    sweep.say_what_finished_runs_get(
        grid(tmp_path, "point", ["north"], ["metra", "lsd"], [0], flags=("--epochs", "8", "--hidden", "32"))
    )
    assert capsys.readouterr().err == ""  # more epochs: a resume takes them
    new = grid(tmp_path, "point", ["north"], ["metra", "lsd"], [0], flags=("--epochs", "4", "--hidden", "48"))
    sweep.say_what_finished_runs_get(new)
    err = capsys.readouterr().err.splitlines()
    assert err == [
        f"warning: {spec.out} resumes from its checkpoint with --preset cpu -- --epochs 4 --hidden 32, not "
        "--preset cpu -- --epochs 4 --hidden 48 (--hidden 32, not 48); the new flags do not apply to it "
        "(remove it to start it anew)"
        for spec in new
    ]


def test_an_interrupted_run_resumed_with_its_own_flags_keeps_its_sweep_run_json(tmp_path, monkeypatch):
    """Was: rewritten with the rerun's flags, which the resumed run does not run with."""
    first = RunSpec("point", "north", "metra", 0, str(tmp_path / "run"), flags=("--epochs", "4", "--hidden", "32"))
    record = tmp_path / "run" / "sweep_run.json"
    launched = []

    def resumed(cmd: list[str]) -> int:  # `collie train --resume` to the run's end, with its own config
        launched.append(cmd)
        summary = tmp_path / "run" / "summary.json"
        summary.write_text(json.dumps({**json.loads(summary.read_text()), "status": "finished"}))
        return 0

    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: resumed(cmd))
    interrupted(first)
    run_one(replace(first, flags=("--epochs", "4", "--hidden", "48")))  # resumed with --hidden 32, its own
    assert launched[-1][-1] == "--resume" and json.loads(record.read_text())["flags"] == list(first.flags)
    interrupted(first)
    more = replace(first, flags=("--epochs", "8", "--hidden", "32"))  # a resume takes more epochs: the run's now
    run_one(more)
    assert len(launched) == 2 and json.loads(record.read_text())["flags"] == list(more.flags)
    interrupted(more)
    unread = replace(more, flags=(*more.flags, "--total-queries", "20"))  # a key METRA does not read: kept too
    run_one(unread)
    assert len(launched) == 3 and json.loads(record.read_text())["flags"] == list(more.flags)


def test_warnings_name_only_the_keys_that_matter_to_the_runs_method(tmp_path, capsys):
    """Was: a METRA run warned of --diayn, DIAYN's own option, and of COLLIE's label budget."""
    first = ("--epochs", "4", "--hidden", "32")
    for spec in grid(tmp_path / "stopped", "point", ["north"], ["metra", "diayn"], [0], flags=first):
        interrupted(spec)
    rerun = grid(tmp_path / "stopped", "point", ["north"], ["metra", "diayn"], [0], flags=(*first[:3], "48"))
    sweep.say_what_finished_runs_get([replace(spec, flags=(*spec.flags, "--diayn", "sphere")) for spec in rerun])
    metra, diayn = capsys.readouterr().err.splitlines()
    assert "(--hidden 32, not 48); the new flags do not apply" in metra
    assert "(--diayn reference, not sphere; --hidden 32, not 48); the new flags do not apply" in diayn

    for spec in grid(tmp_path / "done", "point", ["north"], ["metra", "collie"], [0], flags=first):
        interrupted(spec, status="finished")
    longer = grid(tmp_path / "done", "point", ["north"], ["metra", "collie"], [0], flags=("--epochs", "8"))
    sweep.say_what_finished_runs_get(
        [replace(s, flags=(*s.flags, "--hidden", "32", "--total-queries", "20")) for s in longer]
    )
    said = capsys.readouterr()
    assert said.out == f"{longer[0].out}: finished at 4 epochs; extended to 8 (resumed from its checkpoint)\n"
    assert said.err == (  # COLLIE's label budget is METRA's no concern: only the COLLIE run is not rerun
        f"warning: {longer[1].out} finished with --preset cpu -- --epochs 4 --hidden 32, not --preset cpu -- "
        "--epochs 8 --hidden 32 --total-queries 20 (--epochs 4, not 8; --total-queries 40, not 20); not rerun "
        "(remove it to rerun)\n"
    )


@pytest.mark.parametrize(
    ("flags", "named"),
    [("--bogus 1", "unrecognized arguments: --bogus 1"), ("--trajectories 0", "--trajectories must be ≥ 1")],
)
def test_downstream_flags_are_checked_up_front_only_with_downstream(tmp_path, capsys, monkeypatch, flags, named):
    """Without --downstream no downstream task runs, so its flags are refused by nobody (was: exit 2)."""
    from collie.cli import main

    monkeypatch.setattr(sweep.Stop, "run", lambda _self, cmd, **kw: pytest.fail(f"launched {cmd}"))
    finished(tmp_path / "point-north-lsd-s0")  # nothing to train: only the up-front check could refuse
    argv = ["sweep", "--tasks", "north", "--methods", "lsd", "--seeds", "1", "--out", str(tmp_path), "--no-report"]
    assert main([*argv, "--downstream", "--downstream-flags", flags]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie sweep: error: --downstream-flags '{flags}': python -m trainer.downstream would ")
    assert named in err and len(err.splitlines()) == 1, err
    assert main([*argv, "--downstream-flags", flags]) == 0
    assert "--downstream-flags" not in capsys.readouterr().err


# a training refused for memory a running run was promised (exit EX_TEMPFAIL, as `collie train`)
# while argv[1] is absent; each start is a line in argv[2]
REFUSED_WHILE = (
    "import sys, pathlib; open(sys.argv[2], 'a').write('x\\n'); "
    "sys.exit(0 if pathlib.Path(sys.argv[1]).exists() else 75)"
)


def test_runs_refused_for_memory_a_running_sibling_holds_start_again_once_it_ends(tmp_path, capsys):
    """Two runs refused while a third holds the memory wait for its end, each started once more
    then; a refused run's own end frees nothing and wakes no one (they had restarted each other)."""
    stop, done = sweep.Stop(), tmp_path / "holder-done"
    starts = [str(tmp_path / f"{name}.starts") for name in ("a", "b")]
    holds = (  # until both were refused once (however slowly they start), then 3 s more
        "import time, pathlib\n"
        "deadline = time.monotonic() + 60\n"
        f"while not all(pathlib.Path(p).exists() for p in {starts!r}) and time.monotonic() < deadline:\n"
        "    time.sleep(0.05)\n"
        f"time.sleep(3); pathlib.Path({str(done)!r}).touch()"
    )
    holder = [sys.executable, "-c", holds]
    threads = [threading.Thread(target=stop.run, args=(holder,))]
    for name in ("a", "b"):
        cmd = [sys.executable, "-c", REFUSED_WHILE, str(done), str(tmp_path / f"{name}.starts")]
        threads.append(threading.Thread(target=sweep._call, args=(cmd, tmp_path / f"{name}.log", stop)))
    began = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert time.monotonic() - began > 2.5  # they waited for the holder's end
    assert [(tmp_path / f"{n}.starts").read_text().count("x") for n in ("a", "b")] == [2, 2]
    assert "a waits for a run to end: it needs memory promised to them" in capsys.readouterr().err
    # with no run of the sweep running it is the run's failure, at once: the memory is held elsewhere
    with pytest.raises(RuntimeError, match=r"^failed \(75\): .* — see .*c\.log$"):
        cmd = [sys.executable, "-c", REFUSED_WHILE, str(tmp_path / "never"), str(tmp_path / "c.starts")]
        sweep._call(cmd, tmp_path / "c.log", stop)
    assert (tmp_path / "c.starts").read_text() == "x\n"


def test_a_finished_run_of_a_task_file_edited_since_is_warned_of_naming_its_rule(tmp_path, capsys):
    """Was: no word; the report then averaged it with the seeds trained by the edited file's rule."""
    from trainer.config import make_config
    from trainer.task_choice import choose_rule

    spec_file = tmp_path / "charger.toml"
    spec_file.write_text(CHARGER)
    (spec,) = grid(tmp_path / "runs", "point", ["charger"], ["metra"], [0], task_files={"charger": str(spec_file)})
    interrupted(spec, status="finished")
    cfg = make_config("cpu", "point", method="metra", task="charger", task_file=str(spec_file), seed=0)
    (Path(spec.out) / "task.json").write_text(json.dumps(choose_rule(cfg).to_json()))
    sweep.say_what_finished_runs_get([spec])
    assert capsys.readouterr().err == ""  # the same file: the same run
    saved = (Path(spec.out) / "task.json").read_text()
    (Path(spec.out) / "task.json").unlink()  # a run from before task.json: its rule unknown, not another
    sweep.say_what_finished_runs_get([spec])
    assert capsys.readouterr().err == ""
    (Path(spec.out) / "task.json").write_text(saved)
    spec_file.write_text(CHARGER.replace("radius = 15", "radius = 25"))
    sweep.say_what_finished_runs_get([spec])
    said = capsys.readouterr().err
    assert re.search(r"finished with another configuration \(the task file's rule \w{8}, not \w{8}\); not rerun", said)
