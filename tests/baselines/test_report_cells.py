"""`collie report`: what a cell and its row name say — one name per configuration in every column,
how many seeds a cell holds, which copy of a run counts, downstream results of another protocol or
an older epoch — and that its figures stay readable."""

import csv
import json
import math

import numpy as np
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure

from trainer.config import make_config
from trainer.report import format_cell, write_report

from .test_report import fake_run

SHORT = dict(epochs=20, warmup=4, feedback_every=2)  # a 20-epoch run of the cpu preset
SHORT_NAME = "COLLIE (epochs=20, feedback_every=2, warmup=4)"


def point_config(**more):
    return make_config("cpu", "point", method="collie", **more).to_dict()


def table_of(md: str, title: str) -> list[str]:
    return md.split(f"## {title}")[1].split("##")[0].strip().splitlines()


def test_a_configuration_has_one_row_name_in_every_column(tmp_path):
    """It was "COLLIE (epochs=20, …)" in the column where a default run shared its cell and plain
    "COLLIE" (the default run's row) in the other."""
    runs = tmp_path / "runs"
    fake_run(runs, "point", "north", "collie", 0, 10.0, config=point_config())
    fake_run(runs, "point", "north", "collie", 1, 20.0, config=point_config(**SHORT))
    fake_run(runs, "point", "range", "collie", 1, 30.0, config=point_config(**SHORT))
    md = write_report([runs], tmp_path / "report", figures=False)["markdown"].read_text()
    assert table_of(md, "Safe state coverage (Table 1)")[2:] == [
        "| COLLIE | 10.00 | – |",
        f"| {SHORT_NAME} | 20.00 | 30.00 |",
    ]


def test_a_run_that_departs_from_its_preset_says_so_alone_in_the_report(tmp_path):
    fake_run(tmp_path / "runs", "point", "north", "collie", 0, 20.0, config=point_config(**SHORT))
    md = write_report([tmp_path / "runs"], tmp_path / "report", figures=False)["markdown"].read_text()
    assert f"| {SHORT_NAME} | 20.00 |" in md
    assert f"depart from the defaults of preset cpu, the same in every column: {SHORT_NAME}." in md


def test_a_run_found_twice_counts_the_copy_that_holds_the_most(tmp_path):
    """A `collie rescore`-like copy (no wall time, no zero-shot result) sorted first and was counted."""
    zero_shot = {"zero_shot": {"mean": 5.0, "best": 9.0}}
    bare = fake_run(tmp_path / "a", "point", "north", "metra", 0, 3.0)
    summary = json.loads((bare / "summary.json").read_text())
    (bare / "summary.json").write_text(json.dumps({k: v for k, v in summary.items() if k != "wall_s"}))
    full = fake_run(tmp_path / "b", "point", "north", "metra", 0, 3.0, downstream=zero_shot)
    md = write_report([tmp_path / "a", tmp_path / "b"], tmp_path / "report", figures=False)["markdown"].read_text()
    assert table_of(md, "Zero-shot motion return (Table 3)")[2] == "| METRA | 5.00 | 9.00 |"
    assert table_of(md, "Wall time per run (s)")[2] == "| METRA | 10 |"
    said = f"`{bare}` (the same run as `{full}`, which is the one counted: it has the zero-shot result and wall time"
    assert said + " this copy lacks)" in md


def test_a_cell_says_how_many_seeds_it_holds_where_they_differ():
    assert format_cell([39.0, math.nan], 0) == "39 (1 of 2 seeds)"  # was "39", as if the cell's
    assert format_cell([39.0, None, 41.0], 0, most=3) == "40 ± 1 (2 of 3 seeds)"
    assert format_cell([53.0], 2, most=3) == "53.00 (n=1)"
    assert format_cell([53.0, 55.0, 54.0], 2, most=3) == "54.00 ± 1.00"
    assert format_cell([math.nan], 2, most=3) == "–"


def test_report_md_and_metrics_csv_count_the_same_seeds(tmp_path):
    runs = tmp_path / "runs"
    fake_run(runs, "point", "north", "oracle", 0, 9.0)
    timeless = fake_run(runs, "point", "north", "oracle", 1, 7.0)
    summary = json.loads((timeless / "summary.json").read_text())
    (timeless / "summary.json").write_text(json.dumps({**summary, "wall_s": None}))
    fake_run(runs, "point", "range", "oracle", 0, 3.0)
    paths = write_report([runs], tmp_path / "report", figures=False)
    md = paths["markdown"].read_text()
    assert table_of(md, "Wall time per run (s)")[2] == "| Oracle | 10 (1 of 2 seeds) | 10 (n=1) |"
    assert table_of(md, "Safe state coverage (Table 1)")[2] == "| Oracle | 8.00 ± 1.41 | 3.00 (n=1) |"
    rows = list(csv.DictReader(paths["metrics_csv"].read_text().splitlines()))
    wall = next(r for r in rows if r["metric"] == "wall_s" and r["task"] == "north")
    assert (float(wall["mean"]), wall["n"], wall["seeds"]) == (10.0, "1", "0")  # was nan over n=2


def test_a_zero_shot_cell_mixing_trajectory_counts_is_marked(tmp_path):
    runs = tmp_path / "runs"
    for seed, trajectories in enumerate([160, 80]):
        result = {"mean": 10.0 + seed, "best": 20.0 + seed, "trajectories": trajectories}
        fake_run(runs, "point", "north", "collie", seed, 1.0, downstream={"zero_shot": result})
        fake_run(runs, "point", "north", "metra", seed, 1.0, downstream={"zero_shot": {**result, "trajectories": 160}})
    md = write_report([runs], tmp_path / "report", figures=False)["markdown"].read_text()
    table = table_of(md, "Zero-shot motion return (Table 3)")
    assert table[2] == "| METRA | 10.50 ± 0.71 | 20.50 ± 0.71 |"
    assert table[3] == "| COLLIE | 10.50 ± 0.71 [1] | 20.50 ± 0.71 [1] |"
    assert "[1] averages results over 80 and 160 trajectories per run." in table


def test_a_downstream_result_older_than_its_run_is_marked(tmp_path):
    """Resumed and trained from epoch 60 to 70 after its downstream task ran: the skills judged are
    not the run's final ones."""
    runs = tmp_path / "runs"
    for seed, epoch in enumerate([70, 60]):
        result = {"mean": 10.0, "best": 20.0, "trajectories": 160, "epoch": epoch}
        run = fake_run(runs, "point", "north", "collie", seed, 1.0, downstream={"zero_shot": result})
        summary = json.loads((run / "summary.json").read_text())
        (run / "summary.json").write_text(json.dumps({**summary, "epoch": 70, "epochs_done": 70}))
    md = write_report([runs], tmp_path / "report", figures=False)["markdown"].read_text()
    table = table_of(md, "Zero-shot motion return (Table 3)")
    assert table[2] == "| COLLIE | 10.00 ± 0.00 [1] | 20.00 ± 0.00 [1] |"
    assert "[1] seed 1's result is from epoch 60 of 70 (computed before it trained on)." in table
    assert "Trajectories per run: 160." in table


def _captured_figures(monkeypatch) -> list[Figure]:
    """The figures saved from now on, kept for a look at their layout."""
    saved: list[Figure] = []
    save = Figure.savefig

    def keep(fig, *args, **kwargs):
        saved.append(fig)
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return saved


def test_report_figure_titles_do_not_run_into_each_other(tmp_path, monkeypatch):
    """Long row names ran into the next panel's title, the suptitle and the x axis of the panel above."""
    runs = tmp_path / "runs"
    long = dict(SHORT, distance="l2", queries_per_session=3, total_queries=24)
    settings = [long, dict(long, distance="temporal"), SHORT, dict(SHORT, queries_per_session=3), {}]
    for seed, more in enumerate(settings):  # five panels: two rows of them
        fake_run(runs, "point", "north", "collie", seed, 1.0, config=point_config(**more))
    saved = _captured_figures(monkeypatch)
    write_report([runs], tmp_path / "report")
    (fig,) = saved
    renderer = fig.canvas.get_renderer()
    titles = [ax.title.get_window_extent(renderer) for ax in fig.axes]
    assert len(titles) == 5
    suptitle = fig._suptitle.get_window_extent(renderer)
    for i, title in enumerate(titles):
        assert not title.overlaps(suptitle), i
        for j, ax in enumerate(fig.axes):
            theirs = (ax.get_window_extent(renderer), ax.xaxis.get_tightbbox(renderer), titles[j])
            assert j == i or not any(title.overlaps(b) for b in theirs), (i, j)
    assert all(t.x0 >= 0 and t.x1 <= fig.bbox.x1 and t.y1 <= fig.bbox.y1 for t in titles)


def test_the_guidance_maps_legend_shows_the_markers_it_draws(tmp_path, monkeypatch):
    from trainer.plots import plot_guidance_map

    saved = _captured_figures(monkeypatch)
    xy = [np.stack([np.linspace(0, 3, 8), np.linspace(0, 1, 8)], 1)]
    labelled = [(np.array([[1.0, 0.5], [2.0, 0.7]]), 2), (np.array([[0.5, 0.2]]), 0)]
    plot_guidance_map(xy, [np.linspace(0, 2, 8)], tmp_path / "g.png", labelled=labelled)
    (fig,) = saved
    ax = fig.axes[0]
    drawn = {tuple(c.get_facecolor()[0]) for c in ax.collections[1:]}  # the labelled states
    handles = ax.get_legend().legend_handles
    assert len(handles) == len(drawn) == 2
    for handle in handles:
        assert handle.get_marker() == "x"  # was "o": circles in the legend, crosses on the map
        assert to_rgba(handle.get_markeredgecolor()) in drawn  # in the colour of its label


def charger_run(root, seed: int, radius: float, cov: float):
    """A finished METRA run of a task file named charger whose pit reaches `radius` (its task.json)."""
    from collie.tasks.task_file import load_task_file

    spec = root.parent / f"charger-{radius:g}.toml"
    spec.write_text(
        f'name = "charger"\ndescription = "Stay near the charger."\n[[regions]]\nkind = "outside_disc"\n'
        f'desirability = "bad"\ncentre = [0, 0]\nradius = {radius}\n'
    )
    cfg = make_config("cpu", "point", method="metra", task="charger", task_file=str(spec), seed=seed).to_dict()
    run = fake_run(root, "point", "charger", "metra", seed, cov, config=cfg)
    definition = load_task_file(spec, None, "point", layout_seed=seed).to_json()
    (run / "task.json").write_text(json.dumps({"definition": definition, "instruction": None}))
    return run


def test_runs_of_two_task_files_of_one_name_are_two_rows_never_one_averaged_cell(tmp_path):
    """Was: seed 0 judged by a 15-unit pit and seed 1 by a 40-unit one averaged in one cell, and the
    same seed in another root left out as "the same run"."""
    charger_run(tmp_path / "a", 0, 15, 10.0)
    charger_run(tmp_path / "a", 1, 15, 20.0)
    charger_run(tmp_path / "b", 0, 40, 90.0)
    md = write_report([tmp_path / "a", tmp_path / "b"], tmp_path / "report", figures=False)["markdown"].read_text()
    rows = table_of(md, "Safe state coverage (Table 1)")[2:]
    cells = sorted(row.split(" | ")[1].removesuffix(" |") for row in rows)
    assert cells == ["15.00 ± 7.07", "90.00 (n=1)"] and all(row.startswith("| METRA (rule=") for row in rows)
    assert "the same run as" not in md
    assert "a digest of the rule a task file gave the run" in md


def test_a_figures_panels_share_one_extent_so_skills_compare_by_eye(tmp_path, monkeypatch):
    """Was: each panel scaled to its own skills, an Oracle's ±10 drawn as large as METRA's ±50."""
    runs = tmp_path / "runs"
    fake_run(runs, "point", "north", "metra", 0, 1.0)
    small = fake_run(runs, "point", "north", "oracle", 0, 1.0)
    saved = np.load(small / "eval_latest.npz")
    np.savez(small / "eval_latest.npz", xy=saved["xy"] / 5, skill=saved["skill"], epoch=1)
    figures = _captured_figures(monkeypatch)
    write_report([runs], tmp_path / "report")
    (fig,) = figures
    assert len(fig.axes) == 2
    assert fig.axes[0].get_xlim() == fig.axes[1].get_xlim() and fig.axes[0].get_ylim() == fig.axes[1].get_ylim()
    assert fig.axes[1].get_xlim()[1] >= 10  # the wider panel's reach
