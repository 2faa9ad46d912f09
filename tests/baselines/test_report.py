"""`collie report` on synthetic run folders: paper-format cells, method order, CSV, figures."""

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from collie.cli import main
from trainer.config import make_config
from trainer.report import format_cell, write_report


def fake_run(
    root,
    env,
    task,
    method,
    seed,
    cov,
    status="finished",
    variant="",
    downstream=None,
    corner_cov=None,
    corner=True,
    config=None,
):
    """A finished run folder. Its corner-rule figures equal the headline ones unless `corner_cov` is
    given; `corner=False` writes none (a run from before the corner rule); `config`: more of its
    config (a whole one, from make_config, for instance)."""
    name = f"{env}-{task}-{method}{'+' + variant if variant else ''}-s{seed}"
    d = root / name
    d.mkdir(parents=True)
    cfg = {**(config or {}), "env": env, "task": task, "method": method, "seed": seed}
    scores = {
        "safe_coverage": cov,
        "safe_ratio": 0.5 + seed / 10,
        "composite_coverage": cov,
        "weighted_composite_coverage": cov + 1,
    }
    corners = {f"{rule}_{k}": v for k, v in scores.items() for rule in ("visited", "corner")} if corner else {}
    if corner and corner_cov is not None:
        corners["corner_safe_coverage"] = corner_cov
    summary = {"status": status, **scores, **corners, "wall_s": 10.0, "config": cfg}
    (d / "summary.json").write_text(json.dumps(summary))
    if variant:
        (d / "sweep_run.json").write_text(json.dumps({"variant": variant}))
    if downstream:
        (d / "downstream.json").write_text(json.dumps(downstream))
    angles = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    xy = np.stack([np.cos(angles), np.sin(angles)], 1)[:, None, :] * np.arange(11)[None, :, None]
    np.savez(d / "eval_latest.npz", xy=xy, skill=np.stack([np.cos(angles), np.sin(angles)], 1), epoch=1)
    return d


def test_format_cell_is_mean_and_sample_std():
    assert format_cell([4, 4, 4, 4, 5], 2) == "4.20 ± 0.45"  # the paper's DIAYN cell
    assert format_cell([3.0], 2) == "3.00"
    assert format_cell([], 2) == "–"


def test_report_tables_csv_and_figures(tmp_path):
    runs = tmp_path / "runs"
    for seed, cov in enumerate([100.0, 120.0]):
        fake_run(
            runs, "point", "north", "collie", seed, cov, downstream={"zero_shot": {"mean": 10.0 + seed, "best": 20.0}}
        )
        fake_run(runs, "point", "north", "metra", seed, -cov)
        fake_run(runs, "point", "north", "dodont", seed, 5.0)
    fake_run(runs, "point", "range", "collie", 0, 50.0, variant="additive")
    fake_run(runs, "point", "north", "diayn", 0, 1.0, status="running")
    paths = write_report([runs], tmp_path / "report")
    md = paths["markdown"].read_text()
    table = md.split("## Safe state coverage (Table 1)")[1].split("##")[0]
    lines = [ln for ln in table.strip().splitlines()]
    assert lines[0] == "| method | point north | point range |"
    body = [ln.split(" | ")[0].lstrip("| ") for ln in lines[2:]]
    assert body == ["METRA", "DoDont*", "COLLIE", "COLLIE (additive)"]  # the paper's order, variants last
    assert "| COLLIE | 110.00 ± 14.14 | – |" in table
    assert "| METRA | -110.00 ± 14.14 | – |" in table
    assert "| COLLIE (additive) | – | 50.00 (n=1) |" in table  # fewer seeds than the others
    assert "0.550 ± 0.071" in md  # safe ratio, three digits
    assert "Zero-shot motion return (Table 3)" in md and "10.50 ± 0.71" in md
    assert "point-north-diayn-s0" in md and "(running)" in md  # unfinished: listed, left out
    assert "DIAYN" not in table
    rows = list(csv.DictReader(paths["metrics_csv"].read_text().splitlines()))
    cov = [r for r in rows if r["label"] == "COLLIE" and r["metric"] == "safe_coverage" and r["task"] == "north"]
    assert len(cov) == 1 and float(cov[0]["mean"]) == 110.0 and cov[0]["n"] == "2" and cov[0]["seeds"] == "0 1"
    assert any(r["metric"] == "zero_shot_best" for r in rows)
    assert len(list(csv.DictReader(paths["runs_csv"].read_text().splitlines()))) == 7
    for name in ("skills_point_north.png", "skills_point_range.png"):
        assert (tmp_path / "report" / "figures" / name).stat().st_size > 1000
        assert f"figures/{name}" in md


def test_collie_report_cli(tmp_path, capsys):
    import argparse

    from trainer import report

    fake_run(tmp_path, "point", "north", "oracle", 0, 9.0)

    def args(root: Path) -> argparse.Namespace:
        return argparse.Namespace(roots=[str(root)], out=None, no_figures=True, bin_rule="corner")

    assert report.run(args(tmp_path)) == 0
    assert "| Oracle | 9.00 |" in capsys.readouterr().out
    assert '"(paper)" columns' not in (tmp_path / "report" / "report.md").read_text()  # the paper has no point mass
    assert report.run(args(tmp_path / "nope")) == 2
    (tmp_path / "empty").mkdir()
    assert report.run(args(tmp_path / "empty")) == 2
    assert f"no run folder (none has summary.json) under {tmp_path / 'empty'}" in capsys.readouterr().err
    assert not (tmp_path / "empty" / "report").exists()
    (tmp_path / "a-file").write_text("kept")
    taken = argparse.Namespace(**{**vars(args(tmp_path)), "out": str(tmp_path / "a-file")})
    assert report.run(taken) == 2  # not FileExistsError's traceback
    assert f"collie report: error: --out {tmp_path / 'a-file'} is a file, not a folder" in capsys.readouterr().err
    assert (tmp_path / "a-file").read_text() == "kept"


def test_report_uses_the_corner_rule_and_prints_the_paper_beside_ours(tmp_path):
    runs = tmp_path / "runs"
    fake_run(runs, "ant", "north", "collie", 0, 900.0, corner_cov=950.0)
    fake_run(runs, "ant", "north", "collie", 1, 1000.0, corner_cov=1050.0)
    fake_run(runs, "ant", "north", "metra", 0, -10.0, corner=False)  # predates the corner figures
    fake_run(runs, "point", "north", "collie", 0, 7.0)
    md = write_report([runs], tmp_path / "report", figures=False)["markdown"].read_text()
    table = md.split("## Safe state coverage (Table 1)")[1].split("##")[0]
    lines = table.strip().splitlines()
    assert lines[0] == "| method | ant north | ant north (paper) | point north |"
    assert "| METRA | -10.00 (n=1)† | -1425.80 ± 756.14 | – |" in table  # visited value, marked
    assert "| COLLIE | 1000.00 ± 70.71 | 1333.20 ± 129.10 | 7.00 (n=1) |" in table  # corner: 950, 1050
    ratio = md.split("## Safe state ratio (Table 2)")[1].split("##")[0]
    assert "0.969 ± 0.025" in ratio  # the paper's 96.9 % ± 2.5
    runs_csv = list(csv.DictReader((tmp_path / "report" / "runs.csv").read_text().splitlines()))
    row = next(r for r in runs_csv if r["method"] == "collie" and r["env"] == "ant" and r["seed"] == "0")
    assert float(row["safe_coverage"]) == 950.0 and float(row["visited_safe_coverage"]) == 900.0
    assert "coverage by the reference's corner bin rule (as the paper)" in md

    visited = write_report([runs], tmp_path / "visited", figures=False, bin_rule="visited")["markdown"].read_text()
    table = visited.split("## Safe state coverage (Table 1)")[1].split("##")[0]
    assert "| COLLIE | 950.00 ± 70.71 |" in table  # the visited figures: 900, 1000
    assert "| METRA | -10.00 (n=1)† |" in table and "coverage by the visited bin rule (--bin-rule)" in visited


@pytest.mark.parametrize("rule", ["corner", "visited"])
def test_runs_csv_names_each_rows_bin_rule_and_marks_an_old_run_as_report_md_does(tmp_path, rule):
    """runs.csv gave an old run's headline figures (by the rule of then) beside the others' without
    saying so; report.md marks its cells †."""
    runs = tmp_path / "runs"
    fake_run(runs, "ant", "north", "collie", 0, 900.0, corner_cov=950.0)
    fake_run(runs, "ant", "north", "metra", 0, -10.0, corner=False)  # from before `bin_rule`: its headline
    fake_run(runs, "ant", "north", "dodont", 0, 3.0, corner=False, config={"bin_rule": "corner"})
    md = write_report([runs], tmp_path / "report", figures=False, bin_rule=rule)["markdown"].read_text()
    table = md.split("## Safe state coverage (Table 1)")[1].split("##")[0]
    csv_rows = list(csv.DictReader((tmp_path / "report" / "runs.csv").read_text().splitlines()))
    said = {r["method"]: (r["bin_rule"], r["safe_coverage"]) for r in csv_rows}
    assert said == {
        "collie": (rule, "950.0" if rule == "corner" else "900.0"),
        "metra": ("visited†", "-10.0"),  # what runs before `bin_rule` binned by (FIRST_VERSION)
        "dodont": ("corner†", "3.0"),  # its headline, by the rule it ran with
    }
    for method, label in (("collie", "COLLIE"), ("metra", "METRA"), ("dodont", "DoDont*")):
        cell = next(line for line in table.splitlines() if line.startswith(f"| {label}")).split(" | ")[1]
        assert cell.endswith("†") == said[method][0].endswith("†"), (method, cell)


def test_report_shows_the_safe_ratio_outside_the_start_bins_for_2d_bodies(tmp_path):
    runs = tmp_path / "runs"
    ant = fake_run(runs, "ant", "north", "collie", 0, 1.0)
    fake_run(runs, "half_cheetah", "right", "collie", 0, 1.0)  # a 1-D body: no start block
    standing = [(0.1, 0.1), (-0.1, 0.1), (0.1, -0.1), (-0.1, -0.1), (0.1, 0.1)]
    north = [(0.1, 0.1), (0.5, 1.5), (0.5, 2.5), (0.5, 3.5), (0.5, 4.5)]
    east = [(0.1, 0.1), (3.5, 0.2), (4.5, 0.2), (4.5, 0.2), (4.5, 0.2)]
    np.savez(ant / "eval_latest.npz", xy=np.array([standing, north, east]), skill=np.eye(3)[:, :2], epoch=1)
    md = write_report([runs], tmp_path / "report", figures=False)["markdown"].read_text()
    table = md.split("## Safe ratio outside the start's 2×2 bins")[1].split("##")[0]
    # Outside the four start bins: (0,1)…(0,4) safe, (3,0) and (4,0) bad by their corners.
    assert "| COLLIE | 0.667 | – |" in table, table
    standing = md.split("## Share of the skills ending within one unit of their start")[1].split("##")[0]
    assert "| COLLIE | 0.33 | 0.00 |" in standing, standing  # the cheetah's fake skills run 10 m


def test_the_zero_shot_table_prints_the_papers_table_3_beside_ours(tmp_path):
    runs = tmp_path / "runs"
    for seed, mean in enumerate([-1600.0, -1700.0]):
        zero_shot = {"zero_shot": {"mean": mean, "best": 400.0 + seed}}
        fake_run(runs, "ant", "north", "collie", seed, 1.0, downstream=zero_shot)
    fake_run(runs, "point", "north", "collie", 0, 1.0, downstream={"zero_shot": {"mean": 5.0, "best": 6.0}})
    md = write_report([runs], tmp_path / "report", figures=False)["markdown"].read_text()
    table = md.split("## Zero-shot motion return (Table 3)")[1].split("##")[0]
    lines = table.strip().splitlines()
    assert lines[0] == (
        "| method | ant north (avg) | ant north (avg, paper) | point north (avg) "
        "| ant north (best) | ant north (best, paper) | point north (best) |"
    )
    # COLLIE's North cells of the paper's Table 3: average 1054.25 ± 376.79, best 1460.44 ± 53.12
    assert lines[2] == (
        "| COLLIE | -1650.00 ± 70.71 | 1054.25 ± 376.79 | 5.00 (n=1) "
        "| 400.50 ± 0.71 | 1460.44 ± 53.12 | 6.00 (n=1) |"  # one seed of point north, two of ant north
    )


def test_the_goal_table_prints_the_papers_table_4_beside_not_flip(tmp_path):
    runs = tmp_path / "runs"
    for task in ("right", "not_flip"):
        for seed, mean in enumerate([6.0, 8.0]):
            goal = {"hierarchical": {"mean": mean, "random_skills_mean": -900.0 - seed}}
            fake_run(runs, "half_cheetah", task, "metra", seed, 1.0, downstream=goal)
    md = write_report([runs], tmp_path / "report", figures=False)["markdown"].read_text()
    table = md.split("## Hierarchical Goal return, PPO over frozen skills (Table 4)")[1].split("##")[0]
    lines = table.strip().splitlines()
    # the paper ran its Goal task on the Not-Flip skills only, so only that column has a paper cell
    assert lines[0] == (
        "| method | half_cheetah not_flip | half_cheetah not_flip (paper) | half_cheetah not_flip (random skills) "
        "| half_cheetah right | half_cheetah right (random skills) |"
    )
    assert lines[2] == "| METRA | 7.00 ± 1.41 | 21.58 ± 25.53 | -900.50 ± 0.71 | 7.00 ± 1.41 | -900.50 ± 0.71 |"


BROKEN = [
    ("{not json", "summary.json: not JSON"),
    ("{}", "summary.json: no config in it, and no config.json beside it"),
    ("[1]", "summary.json: not a JSON object"),
    ('{"status": "finished", "config": {"env": "point", "task": "north", "method": "metra", "seed": "x"}}', "seed 'x'"),
]


@pytest.mark.parametrize(("text", "why"), BROKEN)
def test_a_broken_run_folder_is_named_and_left_out_and_given_alone_is_a_one_line_error(tmp_path, capsys, text, why):

    runs = tmp_path / "runs"
    fake_run(runs, "point", "north", "oracle", 0, 9.0)
    broken = runs / "point-north-metra-s0"
    broken.mkdir()
    (broken / "summary.json").write_text(text)
    assert main(["report", str(runs), "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "| Oracle | 9.00 |" in out  # the others are reported
    assert f"Left out (unreadable or twice): `{broken}` ({broken / 'summary.json'}" in out and why in out
    assert main(["report", str(broken), "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie report: error: {broken / 'summary.json'}") and why in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("damage", ["cut short", "a bare .npy"])
def test_a_run_with_a_damaged_final_evaluation_is_named_and_left_out(tmp_path, capsys, damage):

    runs = tmp_path / "runs"
    fake_run(runs, "point", "north", "oracle", 0, 9.0)
    cut = fake_run(runs, "point", "north", "metra", 0, -5.0) / "eval_latest.npz"
    if damage == "cut short":
        cut.write_bytes(cut.read_bytes()[:100])  # a write cut short
    else:
        with cut.open("wb") as f:
            np.save(f, np.zeros(3))
    assert main(["report", str(runs)]) == 0
    out = capsys.readouterr().out
    assert "| Oracle | 9.00 |" in out and "METRA" not in out.split("Left out")[0]
    assert f"Left out (unreadable or twice): `{cut.parent}` ({cut}: not a readable .npz" in out
    assert main(["report", str(cut.parent), "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie report: error: {cut}: not a readable .npz") and len(err.strip().splitlines()) == 1


SIDE_DAMAGE = [
    ("summary.json", {"corner_safe_coverage": "hi"}, "its corner_safe_coverage 'hi' is not a number"),
    ("summary.json", {"corner_safe_coverage": [1]}, "its corner_safe_coverage [1] is not a number"),
    ("downstream.json", {"zero_shot": {}}, "its zero_shot has no number mean or best"),
    ("downstream.json", {"zero_shot": 5}, "its zero_shot is not a JSON object"),
    ("downstream.json", {"hierarchical": {"mean": 1.0}}, "its hierarchical has no number random_skills_mean"),
    ("sweep_run.json", {"variant": 5}, "its variant 5 is not a string"),
]


@pytest.mark.parametrize(("name", "content", "why"), SIDE_DAMAGE)
def test_a_run_with_a_damaged_side_file_is_named_and_left_out(tmp_path, capsys, name, content, why):
    """Was a ValueError, TypeError or KeyError from the tables, with report.md and runs.csv half written."""

    runs = tmp_path / "runs"
    fake_run(runs, "point", "north", "oracle", 0, 9.0)
    damaged = fake_run(runs, "point", "north", "metra", 0, -5.0)
    path = damaged / name
    held = json.loads(path.read_text()) if path.exists() else {}
    path.write_text(json.dumps({**held, **content}))
    assert main(["report", str(runs), "--no-figures"]) == 0
    out = capsys.readouterr().out
    assert "| Oracle | 9.00 |" in out and "METRA" not in out.split("Left out")[0]
    assert f"Left out (unreadable or twice): `{damaged}` ({path}: {why})" in out
    assert main(["report", str(damaged), "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"collie report: error: {path}: {why}") and len(err.strip().splitlines()) == 1


def test_a_run_found_twice_counts_once_and_another_configuration_under_its_name_is_its_own_row(tmp_path):
    from trainer.report import write_report

    run = fake_run(tmp_path / "runs", "point", "north", "oracle", 0, 9.0)
    fake_run(tmp_path / "runs", "point", "north", "oracle", 1, 7.0)
    shutil.copytree(run, tmp_path / "archive" / run.name)  # the run and its archive, given together
    other = fake_run(tmp_path / "older", "point", "north", "oracle", 0, 1.0, config={"epochs": 12})
    roots = [tmp_path / "archive", tmp_path / "runs", tmp_path / "older"]
    text = write_report(roots, tmp_path / "report", figures=False)["markdown"].read_text()
    assert "3 finished runs; seeds per cell: 1, 2." in text and "| Oracle | 8.00 ± 1.41 |" in text
    assert f"`{run}` (the same run as `{tmp_path / 'archive' / run.name}`, which is the one counted)" in text
    assert "| Oracle (epochs=12) | 1.00 (n=1) |" in text and str(other) not in text


def test_runs_whose_configurations_differ_are_never_averaged_into_one_cell(tmp_path):
    """The researcher's mix: METRA at `--preset cpu --epochs 40` (seeds 0, 1) and a smoke seed 2,
    COLLIE beside COLLIE-L2; where and how a run ran (its folder, threads, how often it checkpointed)
    is no difference."""
    from trainer.config import make_config

    def config(preset, method, **more):
        return make_config(preset, "point", method=method, **more).to_dict()

    sw, mix = tmp_path / "sw", tmp_path / "mix"
    for seed, cov in enumerate([10.0, 20.0]):  # seed 1's label budget: no METRA run's concern (it asks none)
        unread = {"total_queries": 99} if seed else {}
        fake_run(
            sw,
            "point",
            "north",
            "metra",
            seed,
            cov,
            config=config("cpu", "metra", epochs=40, out=f"sw/{seed}", **unread),
        )
        ran = config("cpu", "collie", threads=seed, checkpoint_every=10 + seed)
        fake_run(sw, "point", "north", "collie", seed, 30.0 + seed, config=ran)
    fake_run(mix, "point", "north", "metra", 2, 99.0, config=config("smoke", "metra"))
    fake_run(mix, "point", "north", "collie", 0, 5.0, config=config("cpu", "collie", distance="l2"))
    fake_run(mix, "point", "range", "metra", 0, 7.0, config=config("smoke", "metra"))  # alone in its cell
    text = write_report([sw, mix], tmp_path / "report", figures=False)["markdown"].read_text()
    table = text.split("## Safe state coverage (Table 1)")[1].split("##")[0]
    # two presets in the report: every row names its own, and its departures from it
    assert table.strip().splitlines()[2:] == [
        "| METRA (preset=cpu, epochs=40) | 15.00 ± 7.07 | – |",
        "| METRA (preset=smoke) | 99.00 (n=1) | 7.00 (n=1) |",  # the same name in both columns
        "| COLLIE (preset=cpu) | 30.50 ± 0.71 | – |",  # threads 0 and 1, checkpoints every 10 and 11: one configuration
        "| COLLIE (preset=cpu, distance=l2) | 5.00 (n=1) | – |",
    ]
    assert "configurations differ are never averaged" in text
    assert (
        "METRA (preset=cpu, epochs=40), METRA (preset=smoke), COLLIE (preset=cpu), COLLIE (preset=cpu, distance=l2)."
        in text
    )
    rows = list(csv.DictReader((tmp_path / "report" / "metrics.csv").read_text().splitlines()))
    cov = {r["label"]: (r["setting"], r["n"]) for r in rows if r["metric"] == "safe_coverage"}
    assert cov["COLLIE (preset=cpu, distance=l2)"] == ("preset=cpu, distance=l2", "1")
    assert cov["COLLIE (preset=cpu)"] == ("preset=cpu", "2")


def test_a_run_folder_without_its_final_skills_is_in_the_tables_not_the_figures(tmp_path):
    from trainer.report import write_report

    fake_run(tmp_path, "point", "north", "oracle", 0, 9.0)
    (fake_run(tmp_path, "point", "north", "metra", 0, 3.0) / "eval_latest.npz").unlink()  # and no checkpoint
    paths = write_report([tmp_path], tmp_path / "report")
    text = paths["markdown"].read_text()
    assert "| Oracle | 9.00 |" in text and "| METRA | 3.00 |" in text
    assert (tmp_path / "report" / "figures" / "skills_point_north.png").exists()


def test_an_out_that_is_a_run_folder_is_a_one_line_error(tmp_path, capsys):

    run = fake_run(tmp_path / "runs", "point", "north", "metra", 0, 3.0)
    before = sorted(p.name for p in run.iterdir())
    assert main(["report", str(tmp_path / "runs"), "--out", str(run), "--no-figures"]) == 2  # was: written into it
    err = capsys.readouterr().err
    assert err == f"collie report: error: --out {run} is a run folder (it holds summary.json); give another\n"
    assert sorted(p.name for p in run.iterdir()) == before


def test_a_run_still_training_or_killed_before_its_summary_is_listed_and_a_report_of_none_exits_1(tmp_path, capsys):
    """Was: left out without a word ("1 finished runs; seeds per cell: 1", the missing seed unsaid),
    and a report of no finished run exited 0 with tables of dashes."""
    runs = tmp_path / "runs"
    fake_run(runs, "point", "north", "metra", 1, 5.0)
    killed = runs / "point-north-metra-s0"
    killed.mkdir()
    (killed / "config.json").write_text(json.dumps(make_config("cpu", "point", method="metra").to_dict()))
    (runs / "notes").mkdir()
    (runs / "notes" / "config.json").write_text('{"colour": "blue"}')  # no run's
    assert main(["report", str(runs), "--no-figures"]) == 0
    md = (runs / "report" / "report.md").read_text()
    said = f"Left out (not finished): `{killed}` (no summary.json: still training, or killed before it wrote one)"
    assert said in md and "notes" not in md
    capsys.readouterr()
    interrupted = tmp_path / "interrupted"
    fake_run(interrupted, "point", "north", "metra", 0, 5.0, status="interrupted")
    assert main(["report", str(interrupted), "--no-figures"]) == 1
    assert capsys.readouterr().err == (
        f"collie report: error: no finished run to report under {interrupted} "
        f"({interrupted / 'report' / 'report.md'} says why)\n"
    )
