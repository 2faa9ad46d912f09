"""`collie rescore`: a task-free run's final skills judged by another task's rule."""

import json
from pathlib import Path

import numpy as np
import pytest

from collie.cli import main
from collie.tasks import get_task
from trainer.config import make_config
from trainer.loop import Trainer
from trainer.metrics import coverage_metrics
from trainer.report import write_report
from trainer.rescore import RescoreError, rescore

from .test_report import fake_run


def finished_run(root, method="metra", status="finished"):
    d = root / f"ant-north-{method}-s0"
    d.mkdir(parents=True)
    cfg = {"env": "ant", "task": "north", "method": method, "seed": 0, "bin_rule": "corner"}
    summary = {"status": status, "safe_coverage": -1.0, "wall_s": 3000.0, "config": cfg}
    (d / "summary.json").write_text(json.dumps(summary))
    # six skills walking 25 units in six directions: Range (a disc of radius 20 about (0, 5)) loses
    # their far ends, North keeps only the one heading north
    angles = np.linspace(0, 2 * np.pi, 6, endpoint=False) + np.pi / 2
    xy = np.stack([np.cos(angles), np.sin(angles)], 1)[:, None, :] * np.linspace(0, 25, 51)[None, :, None]
    np.savez(d / "eval_latest.npz", xy=xy, pitch=np.zeros(xy.shape[:2]), skill=np.zeros((6, 2)), epoch=5)
    return d, list(xy)


def test_a_metra_run_judged_by_range_has_the_range_figures_and_reads_as_a_range_run(tmp_path, monkeypatch):
    source, xy = finished_run(tmp_path / "runs")
    done = {
        "zero_shot": {"task": "north", "mean": 1.0, "best": 3.0},
        "hierarchical": {"mean": 2.0, "random_skills_mean": 0.5},
    }
    (source / "downstream.json").write_text(json.dumps(done))
    out = rescore(source, "range")
    assert out == source.parent / "ant-range-metra-s0"
    summary = json.loads((out / "summary.json").read_text())
    expected = coverage_metrics(xy, None, get_task("range", "ant"), bin_rule="corner")
    assert summary["safe_coverage"] == expected["safe_coverage"] == expected["corner_safe_coverage"]
    assert summary["corner_n_bad_bins"] == expected["corner_n_bad_bins"] > 0  # the far ends left the disc
    assert summary["config"]["task"] == "range" and summary["rescored_from"] == str(source)
    assert "wall_s" not in summary  # no training time was spent on Range
    monkeypatch.chdir(tmp_path)  # a relative source is kept absolute: read from anywhere, it names the run
    again = rescore(Path("runs") / source.name, "hole", out=tmp_path / "hole")
    assert json.loads((again / "summary.json").read_text())["rescored_from"] == str(source)
    assert json.loads((out / "task.json").read_text())["definition"]["name"] == "range"
    # the Goal task reads no task, so its result carries over; zero-shot used North's rule, so not
    assert json.loads((out / "downstream.json").read_text()) == {"hierarchical": done["hierarchical"]}
    md = write_report([tmp_path / "runs"], tmp_path / "report", figures=False)["markdown"].read_text()
    assert "| method | ant north | ant north (paper) | ant range | ant range (paper) |" in md
    assert '"(paper)" columns: the paper\'s published tables' in md


@pytest.mark.parametrize(
    ("method", "status", "message"),
    [
        ("collie", "finished", "reads its task"),
        ("oracle", "finished", "reads its task"),
        ("metra", "running", "not finished"),
    ],
)
def test_runs_that_cannot_be_rescored_are_refused_with_the_reason(tmp_path, method, status, message):
    source, _ = finished_run(tmp_path, method, status)
    with pytest.raises(RescoreError, match=message):
        rescore(source, "range")


def test_the_command_refuses_an_unknown_task_and_an_existing_run(tmp_path, capsys):
    source, _ = finished_run(tmp_path)
    assert main(["rescore", str(source), "--task", "nowhere"]) == 2
    assert "unknown task 'nowhere'" in capsys.readouterr().err
    assert main(["rescore", str(source), "--task", "north"]) == 2  # its own task
    assert f"{source} is judged by north already" in capsys.readouterr().err
    assert main(["rescore", str(source), "--task", "hole"]) == 0
    assert main(["rescore", str(source), "--task", "hole"]) == 2
    assert "already holds a run (summary.json); remove it first (--keep-existing leaves" in capsys.readouterr().err
    other = tmp_path / "notes"
    other.mkdir()
    (other / "todo.txt").write_text("kept")  # the new folder is renamed into place: only over an empty one
    assert main(["rescore", str(source), "--task", "range", "--out", str(other)]) == 2
    assert (
        f"{other} holds files but no run (no summary.json); remove it or give another --out" in capsys.readouterr().err
    )
    assert [p.name for p in other.iterdir()] == ["todo.txt"]
    (other / "todo.txt").unlink()
    assert main(["rescore", str(source), "--task", "range", "--out", str(other)]) == 0  # an empty one is used


def test_a_refused_run_is_named_and_the_others_are_rescored(tmp_path, capsys):
    """Was: the first refusal, naming no folder, ended the command; the runs after it were never judged."""
    collie_run, _ = finished_run(tmp_path / "a", "collie")
    metra_run, _ = finished_run(tmp_path / "b", "metra")
    assert main(["rescore", str(collie_run), str(metra_run), "--task", "range"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie rescore: error: {collie_run}: ") and "reads its task" in err, err
    assert (tmp_path / "b" / "ant-range-metra-s0" / "summary.json").exists()
    assert main(["rescore", str(collie_run), str(metra_run), "--task", "nowhere"]) == 2
    assert capsys.readouterr().err.count("unknown task 'nowhere'") == 1  # said once, not for each run


def test_an_out_that_is_a_file_is_a_one_line_error(tmp_path, capsys):
    source, _ = finished_run(tmp_path)
    (tmp_path / "a-file").write_text("kept")
    assert main(["rescore", "--task", "range", str(source), "--out", str(tmp_path / "a-file")]) == 2  # was: a traceback
    assert capsys.readouterr().err == f"collie rescore: error: --out {tmp_path / 'a-file'} is a file, not a folder\n"
    (tmp_path / "ant-range-metra-s0").write_text("kept")  # where it goes by default
    with pytest.raises(RescoreError, match="ant-range-metra-s0 is a file, not a folder"):
        rescore(source, "range")
    assert (tmp_path / "a-file").read_text() == (tmp_path / "ant-range-metra-s0").read_text() == "kept"
    with pytest.raises(RescoreError, match="no-such-run is not a folder: give a run folder"):  # was "no summary.json"
        rescore(tmp_path / "no-such-run", "range")
    with pytest.raises(RescoreError, match="is inside the run folder"):  # was: a run made inside its source
        rescore(source, "range", source / "x")


@pytest.mark.slow
def test_a_trained_run_rescored_twice_with_its_downstream_task_judged_by_the_new_rule(tmp_path, capsys, monkeypatch):
    source = tmp_path / "point-north-metra-s0"
    cfg = make_config("smoke", "point", method="metra", task="north", epochs=2, out=str(source))
    Trainer(cfg, progress=False).run()
    args = ["rescore", str(source), "--task", "range", "--keep-existing", "--downstream"]
    assert main(args) == 0
    out = tmp_path / "point-range-metra-s0"
    zero_shot = json.loads((out / "downstream.json").read_text())["zero_shot"]
    assert zero_shot["task"] == "range"  # the motion task's safety rule is the new task's
    assert json.loads((out / "config.json").read_text())["task"] == "range"
    written = (out / "summary.json").stat().st_mtime_ns, (out / "downstream.json").stat().st_mtime_ns
    assert main(args) == 0  # a rerun continues: nothing rescored or evaluated again
    monkeypatch.chdir(tmp_path)  # also when the rerun names the run by another path
    assert main(["rescore", source.name, "--task", "range", "--keep-existing", "--downstream"]) == 0
    assert ((out / "summary.json").stat().st_mtime_ns, (out / "downstream.json").stat().st_mtime_ns) == written
    assert main(["rescore", str(out), "--task", "hole", "--out", str(out), "--keep-existing"]) == 2
    assert "already holds a run" in capsys.readouterr().err  # rescored from another run: still refused
    assert main(["train", "--env", "point", "--out", str(out), "--resume"]) == 2  # its networks only, no replay
    assert f"is {source} judged by another task (collie rescore): resume {source}" in capsys.readouterr().err


def test_a_downstream_task_without_a_checkpoint_is_refused_with_the_reason(tmp_path, capsys):
    source, _ = finished_run(tmp_path)  # summary and final skills, but no checkpoint.pt
    assert main(["rescore", str(source), "--task", "range", "--downstream"]) == 2
    assert "has no checkpoint.pt; no downstream task" in capsys.readouterr().err
    assert (tmp_path / "ant-range-metra-s0" / "summary.json").exists()  # the rescore itself is kept


@pytest.mark.parametrize(
    ("summary", "why"),
    [
        ("{not json", "summary.json: not JSON"),
        ("{}", "summary.json: no config in it"),
        ('{"status": "finished", "config": {"env": "ant", "task": "north", "method": "metra", "seed": "x"}}', "'x'"),
    ],
)
def test_a_broken_summary_is_a_one_line_error_naming_it(tmp_path, capsys, summary, why):
    source, _ = finished_run(tmp_path)
    (source / "summary.json").write_text(summary)
    assert main(["rescore", str(source), "--task", "range"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie rescore: error: {source / 'summary.json'}") and why in err


def test_a_damaged_final_evaluation_is_a_one_line_error_naming_it(tmp_path, capsys):
    source, _ = finished_run(tmp_path)
    saved = source / "eval_latest.npz"
    saved.write_bytes(saved.read_bytes()[:100])
    assert main(["rescore", str(source), "--task", "range"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie rescore: error: {saved}: not a readable .npz") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "ant-range-metra-s0").exists()


def test_the_downstream_command_on_an_archived_run_says_its_networks_are_not_kept(tmp_path, capsys):
    from trainer.downstream.__main__ import main as downstream

    source, _ = finished_run(tmp_path)  # as `collie archive` keeps it: no checkpoint.pt
    (source / "config.json").write_text(json.dumps({"env": "ant", "task": "north", "method": "metra", "seed": 0}))
    assert downstream([str(source)]) == 2
    assert f"downstream: error: {source} has no checkpoint.pt: its networks are not kept" in capsys.readouterr().err
    assert downstream([str(tmp_path / "no-such-run")]) == 2  # was: "has no checkpoint.pt: … an archived run"
    assert (
        f"downstream: error: {tmp_path / 'no-such-run'} is not a folder: give a run folder" in capsys.readouterr().err
    )
    with pytest.raises(SystemExit):
        downstream([str(source), "--trajectories", "0"])
    assert "--trajectories must be ≥ 1, got 0" in capsys.readouterr().err
    stack = tmp_path / "stack"  # a `collie up` folder given for its run (was: "… an archived run holds results only")
    (stack / "trainer").mkdir(parents=True)
    (stack / "trainer" / "checkpoint.pt").write_bytes(b"")
    assert downstream([str(stack)]) == 2
    assert f"downstream: error: {stack} is a collie up folder: give its run, {stack / 'trainer'}" in (
        capsys.readouterr().err
    )


def test_the_downstream_command_on_an_unfinished_run_says_so(tmp_path):
    """Was silent: an interrupted run's skills were evaluated as if it had finished."""
    from trainer.downstream.__main__ import not_finished

    stopped = fake_run(tmp_path, "point", "north", "metra", 0, 1.0, status="interrupted")
    said = not_finished(stopped)
    assert said is not None and said.startswith(f"{stopped} has not finished (status interrupted, epoch")
    assert not_finished(fake_run(tmp_path, "point", "north", "metra", 1, 1.0)) is None
    assert not_finished(tmp_path / "nowhere") is None  # load_skills says what is missing
    training = tmp_path / "training"
    training.mkdir()
    (training / "checkpoint.pt").write_bytes(b"")  # a run still training (or killed): no summary yet
    assert "has not finished (no summary.json: still training" in (not_finished(training) or "")
