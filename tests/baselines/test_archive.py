"""`collie archive`: a finished run's results kept without its checkpoint and replay, and reported
exactly as the run itself."""

import json
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from collie.cli import main
from trainer.archive import ArchiveError, archive
from trainer.config import make_config
from trainer.loop import Trainer
from trainer.report import find_runs, write_report
from trainer.sweep import run_downstream_task

from .test_report import fake_run


@pytest.mark.slow
def test_an_archived_run_reports_as_the_run_itself_without_its_checkpoint_or_replay(tmp_path, capsys):
    runs, kept = tmp_path / "runs", tmp_path / "results"
    source = runs / "point-north-collie-s0"
    cfg = make_config("smoke", "point", method="collie", task="north", epochs=2, out=str(source))
    Trainer(cfg, progress=False).run()
    run_downstream_task(source)
    assert main(["archive", str(source), "--out", str(kept)]) == 0
    out = kept / source.name
    assert f"→ {out}" in capsys.readouterr().out
    names = {p.name for p in out.iterdir()}
    assert {"summary.json", "eval_latest.npz", "config.json", "task.json", "downstream.json", "metrics.jsonl"} <= names
    assert "checkpoint.pt" not in names and "replay" not in names
    assert sum(p.stat().st_size for p in out.iterdir()) < 200_000  # small enough to commit

    from_runs = write_report([runs], tmp_path / "report-runs")
    from_kept = write_report([kept], tmp_path / "report-kept")
    for name in ("markdown", "metrics_csv", "runs_csv"):  # every figure, diagnostic and downstream result
        text = from_kept[name].read_text().replace(str(kept), str(runs)).replace("report-kept", "report-runs")
        assert text == from_runs[name].read_text(), name
    assert "zero_shot" in from_kept["metrics_csv"].read_text()

    assert main(["archive", str(source), "--out", str(kept)]) == 0  # archiving again refreshes it
    other = runs / "elsewhere" / source.name
    other.mkdir(parents=True)
    for name in ("summary.json", "eval_latest.npz"):
        (other / name).write_bytes((source / name).read_bytes())
    summary = json.loads((other / "summary.json").read_text())
    summary["config"] |= {"out": str(other), "threads": 2, "diayn": "sphere"}  # the same run, from another folder
    # (DIAYN's option: no COLLIE run's concern)
    (other / "summary.json").write_text(json.dumps(summary))
    assert main(["archive", str(other), "--out", str(kept)]) == 0
    assert json.loads((out / "summary.json").read_text())["config"]["out"] == str(other)
    summary["config"]["seed"] = 7
    (other / "summary.json").write_text(json.dumps(summary))
    assert main(["archive", str(other), "--out", str(kept)]) == 2
    err = capsys.readouterr().err
    assert f"{out} holds another run of that name (seed 0 archived, 7 here); remove it first" in err


@pytest.mark.parametrize(
    ("files", "status", "message"),
    [
        ({"summary.json"}, "finished", "has no eval_latest.npz"),
        ({"eval_latest.npz"}, "finished", "has no summary.json"),
        ({"summary.json", "eval_latest.npz"}, "running", "not finished"),
    ],
)
def test_what_is_not_a_finished_run_is_refused_with_the_reason(tmp_path, files, status, message):
    source = fake_run(tmp_path, "ant", "north", "metra", 0, 1.0, status=status)
    for name in {"summary.json", "eval_latest.npz"} - files:
        (source / name).unlink()
    with pytest.raises(ArchiveError, match=message):
        archive(source, tmp_path / "results")
    assert not (tmp_path / "results").exists()


def test_a_sweep_folder_is_archived_run_by_run_at_the_same_paths_leaving_out_unfinished_runs(tmp_path, capsys):
    sweep = tmp_path / "runs" / "robots"
    for env, task, method, status in [
        ("ant", "north", "metra", "finished"),
        ("ant", "north", "collie", "running"),
        ("half_cheetah", "right", "metra", "finished"),
    ]:
        fake_run(sweep / env, env, task, method, 0, 1.0, status=status)
    kept = tmp_path / "results" / "robots"
    assert main(["archive", str(sweep), "--out", str(kept)]) == 0
    assert f"left out (not finished): {sweep / 'ant' / 'ant-north-collie-s0'}" in capsys.readouterr().out
    archived = sorted(p.parent.relative_to(kept).as_posix() for p in kept.rglob("summary.json"))
    assert archived == ["ant/ant-north-metra-s0", "half_cheetah/half_cheetah-right-metra-s0"]
    saved = sweep / "ant" / "ant-north-metra-s0" / "eval_latest.npz"
    assert (kept / "ant" / "ant-north-metra-s0" / "eval_latest.npz").read_bytes() == saved.read_bytes()
    assert main(["archive", str(tmp_path / "results"), "--out", str(kept)]) == 0  # nothing archived into itself
    assert main(["archive", str(tmp_path / "nowhere"), "--out", str(kept)]) == 2
    assert "is not a folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["archive", str(tmp_path / "empty"), "--out", str(kept)]) == 2
    assert "holds no run folder" in capsys.readouterr().err


def test_an_out_that_is_a_file_the_folder_given_or_inside_a_run_is_a_one_line_error(tmp_path, capsys):
    sweep = tmp_path / "runs"
    run = fake_run(sweep, "ant", "north", "metra", 0, 1.0)
    other = fake_run(tmp_path / "elsewhere", "ant", "north", "metra", 1, 1.0)
    (tmp_path / "a-file").write_text("kept")
    refused = [
        (sweep, tmp_path / "a-file", f"--out {tmp_path / 'a-file'} is a file, not a folder"),
        (sweep, sweep, f"--out {sweep} is the folder given to archive; give another folder"),  # was: rc 0, nothing
        (run, run, f"--out {run} is the folder given to archive"),
        (run, run / "kept", f"--out {run / 'kept'} is inside the run folder {run}"),  # was: a copy inside itself
        (sweep, run / "kept", f"--out {run / 'kept'} is inside the run folder {run}"),  # a run below the root given
        (other, run / "kept", f"--out {run / 'kept'} is inside the run folder {run}"),  # any run's: was rc 0
    ]
    for given, out, said in refused:
        assert main(["archive", str(given), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"collie archive: error: {said}") and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in run.iterdir()) == ["eval_latest.npz", "summary.json"]
    assert (tmp_path / "a-file").read_text() == "kept"


@pytest.mark.parametrize(("text", "why"), [("{not json", "not JSON"), ("[1]", "not a JSON object")])
def test_an_unreadable_summary_is_named_and_left_out_and_given_alone_is_a_one_line_error(tmp_path, capsys, text, why):
    sweep = tmp_path / "runs"
    fake_run(sweep, "ant", "north", "metra", 0, 1.0)
    (fake_run(sweep, "ant", "north", "metra", 1, 1.0) / "summary.json").write_text(text)
    kept = tmp_path / "results"
    assert main(["archive", str(sweep), "--out", str(kept)]) == 0
    broken = sweep / "ant-north-metra-s1" / "summary.json"
    assert f"left out (unreadable): {broken}: {why}" in capsys.readouterr().out
    assert [p.parent.name for p in kept.rglob("summary.json")] == ["ant-north-metra-s0"]
    assert main(["archive", str(broken.parent), "--out", str(kept)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie archive: error: {broken}: {why}") and len(err.strip().splitlines()) == 1


def test_a_run_that_clashes_with_the_archive_is_named_with_what_differs_and_the_others_are_archived(tmp_path, capsys):
    from trainer.config import make_config

    sweep, kept = tmp_path / "runs", tmp_path / "results"
    for seed in (0, 1):
        out = str(sweep / f"point-north-metra-s{seed}")
        cfg = make_config("cpu", "point", method="metra", seed=seed, out=out).to_dict()
        fake_run(sweep, "point", "north", "metra", seed, 1.0, config=cfg)
    held = kept / "point-north-metra-s0"
    held.mkdir(parents=True)
    cfg = make_config("cpu", "point", method="metra", seed=0, epochs=40, hidden=64).to_dict()
    (held / "summary.json").write_text(json.dumps({"status": "finished", "config": cfg}))
    assert main(["archive", str(sweep), "--out", str(kept)]) == 2
    err = capsys.readouterr().err
    assert (
        f"collie archive: error: {held} holds another run of that name "
        "(epochs 40 archived, 400 here; hidden 64 archived, 256 here); remove it first"
    ) in err
    assert f"collie archive: 1 of 2 runs not archived: {sweep / 'point-north-metra-s0'}" in err
    assert (kept / "point-north-metra-s1" / "eval_latest.npz").exists()  # archived all the same
    assert not (held / "eval_latest.npz").exists()  # the clash left as it was


def test_collie_up_runs_go_by_their_stacks_names(tmp_path, capsys):
    """Every stack's run folder is OUT/trainer: archived by its stack's folder name, two stacks' runs
    sit side by side (given as the run folder or as the stack's folder), not one refused as a clash."""
    kept = tmp_path / "results"
    for stack, env in (("up-point-north", "point"), ("up-ant-north", "ant")):
        (tmp_path / stack).mkdir()
        shutil.move(fake_run(tmp_path / "made", env, "north", "metra", 0, 1.0), tmp_path / stack / "trainer")
        (tmp_path / stack / "up.lock").write_text("")
    assert main(["archive", str(tmp_path / "up-point-north" / "trainer"), "--out", str(kept)]) == 0
    assert main(["archive", str(tmp_path / "up-ant-north"), "--out", str(kept)]) == 0
    assert sorted(p.name for p in kept.iterdir()) == ["up-ant-north", "up-point-north"]
    assert json.loads((kept / "up-ant-north" / "summary.json").read_text())["config"]["env"] == "ant"
    plain = tmp_path / "sweep" / "trainer"  # a folder named trainer outside a stack keeps its name
    plain.parent.mkdir()
    shutil.move(fake_run(tmp_path / "made", "point", "north", "metra", 1, 1.0), plain)
    assert main(["archive", str(plain), "--out", str(kept)]) == 0
    assert (kept / "trainer" / "summary.json").exists()


LEFT_OUT_BY_THE_REPORT = [  # (the file damaged, what it holds then, why the report leaves the run out)
    ("eval_latest.npz", "cut short", "not a readable .npz"),
    ("summary.json", {"corner_safe_coverage": "hi"}, "its corner_safe_coverage 'hi' is not a number"),
    ("downstream.json", {"zero_shot": 5}, "its zero_shot is not a JSON object"),
    ("summary.json", {"config": {"env": "point", "task": "nowhere", "method": "metra", "seed": 0}}, "unknown task"),
]


@pytest.mark.parametrize(("name", "damage", "why"), LEFT_OUT_BY_THE_REPORT)
def test_a_run_the_report_leaves_out_is_not_archived_and_named_with_why(tmp_path, capsys, name, damage, why):
    """Was copied into the archive all the same, where `collie report` then left it out."""
    runs, kept = tmp_path / "runs", tmp_path / "results"
    fake_run(runs, "point", "north", "oracle", 0, 9.0)
    damaged = fake_run(runs, "point", "north", "metra", 0, -5.0)
    path = damaged / name
    if damage == "cut short":
        path.write_bytes(path.read_bytes()[:100])
    else:
        held = json.loads(path.read_text()) if path.exists() else {}
        path.write_text(json.dumps({**held, **damage}))
    said = f"{damaged if why == 'unknown task' else path}: {why}"  # the file, or for a task the run's folder
    assert main(["report", str(runs), "--no-figures", "--out", str(tmp_path / "report")]) == 0
    assert f"`{damaged}` ({said}" in capsys.readouterr().out  # the report leaves it out

    assert main(["archive", str(runs), "--out", str(kept)]) == 0  # as a run whose summary.json is not JSON
    assert f"left out (unreadable): {said}" in capsys.readouterr().out
    assert [p.parent.name for p in kept.rglob("summary.json")] == ["point-north-oracle-s0"]
    assert main(["archive", str(damaged), "--out", str(kept)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie archive: error: {said}") and len(err.strip().splitlines()) == 1, err
    with pytest.raises(ArchiveError, match=re.escape(why)):
        archive(damaged, kept)
    assert not (kept / damaged.name).exists()


# `collie archive` killed -9 (os.kill, not an exception: nothing is cleaned up) as it renames a
# hidden folder whose name ends with argv[1]: `.partial`, the new copy renamed in (between the two
# renames that swap it for the older one), or `.old`, the older copy on its way out (after them).
KILLED_AT_A_RENAME = """
import os, pathlib, signal, sys
from collie.cli import main
rename = pathlib.Path.replace
def dying(self, target):
    if self.is_dir() and self.name.endswith(sys.argv[1]):
        os.kill(os.getpid(), signal.SIGKILL)
    return rename(self, target)
pathlib.Path.replace = dying
sys.exit(main(sys.argv[2:]))
"""


def files_in(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


@pytest.mark.parametrize("killed_renaming", [".partial", ".old"], ids=["between-the-renames", "after-them"])
def test_an_archive_killed_mid_refresh_loses_no_copy_and_its_hidden_folders_are_no_runs(
    tmp_path, capsys, killed_renaming
):
    """Killed between the renames, the archive holds no copy in place but both whole beside it: the
    next archive puts the older one back (and compares with it) before it refreshes. The hidden
    folders hold summary.json but neither `collie report` nor `collie archive` takes them for runs."""
    runs, kept = tmp_path / "runs", tmp_path / "results"
    run = fake_run(runs, "point", "north", "metra", 0, 1.0)
    fake_run(runs, "point", "north", "metra", 1, 1.0)
    assert main(["archive", str(runs), "--out", str(kept)]) == 0
    out, older = kept / run.name, files_in(kept / run.name)
    (run / "downstream.json").write_text(json.dumps({"zero_shot": {"mean": 1.0, "best": 2.0}}))
    argv = ["archive", str(run), "--out", str(kept)]
    killed = subprocess.run([sys.executable, "-c", KILLED_AT_A_RENAME, killed_renaming, *argv], timeout=120)
    assert killed.returncode == -signal.SIGKILL
    between = killed_renaming == ".partial"
    hidden = sorted(p.name.rsplit(".", 1)[1] for p in kept.iterdir() if p.name.startswith("."))
    assert hidden == (["old", "partial"] if between else ["old"])
    assert not out.exists() if between else files_in(out) == files_in(run)

    shown = [] if between else [run.name]  # the run in place, if any; never a hidden copy of it
    found, broken = find_runs([kept])
    assert [r.path.name for r in found] == [*shown, "point-north-metra-s1"] and broken == []
    assert main(["archive", str(kept), "--out", str(tmp_path / "copied")]) == 0
    assert sorted(p.name for p in (tmp_path / "copied").iterdir()) == [*shown, "point-north-metra-s1"]

    clash = fake_run(tmp_path / "other", "point", "north", "metra", 0, 1.0)
    summary = json.loads((clash / "summary.json").read_text())
    summary["config"]["seed"] = 7
    (clash / "summary.json").write_text(json.dumps(summary))
    assert main(["archive", str(clash), "--out", str(kept)]) == 2  # compared with the copy put back
    assert "(seed 0 archived, 7 here)" in capsys.readouterr().err
    assert files_in(out) == (older if between else files_in(run))
    assert main(argv) == 0
    assert files_in(out) == files_in(run)
    assert sorted(p.name for p in kept.iterdir()) == [run.name, "point-north-metra-s1"]  # nothing hidden left


def test_a_run_extended_since_refreshes_its_archive_and_another_rule_of_its_task_name_is_refused(tmp_path, capsys):
    """Was: "holds another run of that name (epochs 12 archived, 16 here)" for the same run resumed
    with more --epochs; and a task file of the same name but another rule replaced it silently."""
    from .test_report_cells import charger_run

    run = charger_run(tmp_path / "runs", 0, 15, 10.0)
    assert main(["archive", str(run), "--out", str(tmp_path / "kept")]) == 0
    summary = json.loads((run / "summary.json").read_text())
    summary["config"]["epochs"] += 4  # `collie train --resume --epochs N`
    (run / "summary.json").write_text(json.dumps(summary))
    assert main(["archive", str(run), "--out", str(tmp_path / "kept")]) == 0
    held = tmp_path / "kept" / run.name
    assert json.loads((held / "summary.json").read_text()) == summary
    summary["config"]["epochs"] -= 8  # an earlier copy, fewer epochs than the archive's: another run
    (run / "summary.json").write_text(json.dumps(summary))
    assert main(["archive", str(run), "--out", str(tmp_path / "kept")]) == 2
    assert "holds another run of that name (epochs" in capsys.readouterr().err
    other = charger_run(tmp_path / "elsewhere", 0, 40, 90.0)
    assert main(["archive", str(other), "--out", str(tmp_path / "kept")]) == 2
    assert re.search(
        r"holds another run of that name \(.*rule '\w{8}' archived, '\w{8}' here\)", capsys.readouterr().err
    )
