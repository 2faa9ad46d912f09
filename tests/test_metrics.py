"""Coverage metrics on hand-built trajectories, and the run figures."""

from __future__ import annotations

import math
import pathlib

import matplotlib.image
import numpy as np
import pytest

from collie.tasks import BAD, GOOD, NEUTRAL, get_task
from trainer import plots
from trainer.metrics import coverage_metrics, off_start_safe_ratio, start_block, travel_metrics


def arr(points: list[tuple[float, float]]) -> np.ndarray:
    return np.array(points, dtype=float)


def test_north_bins_with_a_boundary_inside_one_bin() -> None:
    trajs = [
        arr([(0.5, 0.5), (0.5, 2.5), (0.5, 2.7)]),  # bins (0,0), (0,2) twice: both safe
        arr([(3.2, 3.5), (3.8, 3.5), (3.9, 2.1)]),  # bin (3,3) holds a safe and a bad state; (3,2) bad
        arr([(-5.5, -0.5)]),  # bin (-6,-1) bad
    ]
    m = coverage_metrics(trajs, None, get_task("north"))
    assert (m["n_bins"], m["n_bad_bins"], m["n_neutral_bins"], m["n_good_bins"]) == (5, 3, 2, 0)
    assert m["safe_coverage"] == 2 - 3
    assert m["safe_ratio"] == pytest.approx(0.4)
    assert m["composite_coverage"] == m["safe_coverage"]
    assert m["weighted_composite_coverage"] == 2 - 3
    assert m["n_states"] == 7
    # The bin (3,3) alone: its lower-left corner is safe, but a visited state in it was bad.
    only = coverage_metrics([arr([(3.2, 3.5), (3.8, 3.5)])], None, get_task("north"))
    assert (only["n_bins"], only["n_bad_bins"]) == (1, 1)


def test_composite_task_counts_good_neutral_bad() -> None:
    trajs = [
        arr([(0.2, 10.1), (0.7, 10.9)]),  # bin (0,10): all good
        arr([(5.5, 5.2), (5.1, 5.3)]),  # bin (5,5): neutral + good -> neutral
        arr([(0.5, 30.5), (-8.5, 1.5)]),  # bin (0,30) outside the circle: bad; bin (-9,1) neutral
    ]
    m = coverage_metrics(trajs, None, get_task("range_north"))
    assert (m["n_bins"], m["n_good_bins"], m["n_neutral_bins"], m["n_bad_bins"]) == (4, 1, 2, 1)
    assert m["safe_coverage"] == 3 - 1
    assert m["composite_coverage"] == 1 + 2 - 1
    assert m["weighted_composite_coverage"] == 2 * 1 + 2 - 1
    assert m["safe_ratio"] == pytest.approx(0.75)


def test_one_dimensional_bins_use_x_only() -> None:
    x = np.array([-0.5, 0.5, 1.2, -1.5, -1.2])  # bins -1 (bad), 0, 1, -2 (bad, twice)
    m = coverage_metrics([x], None, get_task("right", "half_cheetah"), position_dims=1)
    assert (m["n_bins"], m["n_bad_bins"], m["n_neutral_bins"]) == (4, 2, 2)
    with_y = np.stack([x, np.array([0.0, 9.0, -9.0, 3.0, 50.0])], axis=1)  # y must not split bins
    assert coverage_metrics([with_y], None, get_task("right"), position_dims=1)["n_bins"] == 4


def test_not_flip_is_judged_from_pitch_of_visited_states() -> None:
    task = get_task("not_flip", "half_cheetah")
    x = np.array([0.2, 0.7, 1.5, 2.5, -0.5])
    pitch = np.array([0.0, 2.0, 0.0, -math.pi / 2, 0.0])  # only the state at x = 0.7 is flipped
    m = coverage_metrics([x], [pitch], task, position_dims=1)
    assert (m["n_bins"], m["n_bad_bins"], m["n_neutral_bins"]) == (4, 1, 3)
    with pytest.raises(ValueError, match="pitch"):
        coverage_metrics([x], None, task, position_dims=1)


def test_bin_size_and_empty_input() -> None:
    pts = arr([(0.001, 0.001), (0.009, 0.002), (0.011, 0.0)])
    assert coverage_metrics([pts], None, get_task("right"), bin_size=0.01)["n_bins"] == 2
    empty = coverage_metrics([], None, get_task("north"))
    assert empty["n_bins"] == 0 and empty["safe_ratio"] == 0.0 and empty["safe_coverage"] == 0.0


def test_matches_a_plain_loop_on_48_random_trajectories() -> None:
    rng = np.random.default_rng(0)
    trajs = [np.cumsum(rng.normal(0, 1.0, (201, 2)), axis=0) for _ in range(48)]
    task = get_task("hole_north")
    per_bin: dict[tuple[int, int], list[int]] = {}
    for t in trajs:
        for p, c in zip(t, task.classify(t), strict=True):
            per_bin.setdefault((math.floor(p[0]), math.floor(p[1])), []).append(int(c))
    expected = [BAD if BAD in v else GOOD if set(v) == {GOOD} else NEUTRAL for v in per_bin.values()]
    m = coverage_metrics(trajs, None, task)
    assert m["n_bins"] == len(per_bin)
    assert m["n_bad_bins"] == expected.count(BAD)
    assert m["n_good_bins"] == expected.count(GOOD)
    assert m["n_neutral_bins"] == expected.count(NEUTRAL)


# ---- figures ---------------------------------------------------------------------------------


def assert_real_png(path: pathlib.Path) -> None:
    image = matplotlib.image.imread(path)
    assert path.stat().st_size > 5_000
    assert image.ndim == 3 and image[..., :3].std() > 0.05  # not a blank canvas


def test_skill_trajectory_plot_2d(tmp_path: pathlib.Path) -> None:
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    skills = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    trajs = [np.linspace((0, 0), 30 * s, 50) for s in skills]
    labelled = [(trajs[2][:20], NEUTRAL), (trajs[0][30:], BAD)]
    out = plots.plot_skill_trajectories(
        trajs, get_task("hole_north"), tmp_path / "fig" / "skills.png", skills=skills, labelled=labelled
    )
    assert out == tmp_path / "fig" / "skills.png"
    assert_real_png(out)
    colours = plots.skill_colours(skills, len(skills))
    assert colours[0] != colours[4]  # opposite directions, different hues


def test_skill_trajectory_plot_1d_and_pitch_task(tmp_path: pathlib.Path) -> None:
    xs = [np.cumsum(np.full(100, d)) for d in np.linspace(-1, 1, 16)]
    one_hot = np.eye(16)
    assert len(set(plots.skill_colours(one_hot, 16))) == 16
    out = plots.plot_skill_trajectories(
        xs, get_task("right", "half_cheetah"), tmp_path / "x.png", skills=one_hot, position_dims=1
    )
    assert_real_png(out)
    flip = plots.plot_skill_trajectories(
        xs, get_task("not_flip", "half_cheetah"), tmp_path / "flip.png", position_dims=1, title="Not-Flip"
    )
    assert_real_png(flip)


def test_curves_plot(tmp_path: pathlib.Path) -> None:
    records = [{"epoch": e, "safe_ratio": e / 100, "safe_coverage": 3 * e} for e in range(0, 100, 10)]
    records.append({"epoch": 100, "loss": 1.0})  # keys may be missing from some records
    out = plots.plot_curves(records, ["safe_ratio", "safe_coverage", "loss"], tmp_path / "curves.png")
    assert_real_png(out)


# ---- the two bin rules (`--bin-rule`) ------------------------------------------------------------


def test_a_robot_standing_at_the_wedge_apex_is_three_quarters_unsafe_by_the_corner_rule() -> None:
    north = get_task("north")
    # Reset noise around the start (0, 0): the four bins around the origin, three with a bad corner.
    standing = [arr([(0.1, 0.1), (-0.1, 0.1), (0.1, -0.1), (-0.1, -0.1)])]
    assert sorted(map(tuple, start_block(standing))) == [(-1, -1), (-1, 0), (0, -1), (0, 0)]
    assert coverage_metrics(standing, None, north, bin_rule="corner")["safe_ratio"] == pytest.approx(0.25)
    assert math.isnan(off_start_safe_ratio(standing, north))  # nothing left outside the start
    # From the start, one skill walks north through bins (0,1)…(0,4) and one east to (3,0), (4,0),
    # whose corners are bad.
    walkers = [
        *standing,
        arr([(0.1, 0.1), *((0.5, y + 0.5) for y in range(1, 5))]),
        arr([(0.1, 0.1), (3.5, 0.2), (4.5, 0.2)]),
    ]
    assert coverage_metrics(walkers, None, north, bin_rule="corner")["safe_ratio"] == pytest.approx(5 / 10)
    assert off_start_safe_ratio(walkers, north) == pytest.approx(4 / 6)
    # A start off the origin moves the block with it: the grid corner nearest (10.4, 9.6) is (10, 10).
    assert sorted(map(tuple, start_block([arr([(10.4, 9.6), (0.0, 0.0)])]))) == [(9, 9), (9, 10), (10, 9), (10, 10)]


def test_corner_rule_judges_a_bin_at_its_lower_left_corner() -> None:
    north = get_task("north")
    # Bin (3,3): corner (3,3) lies on y = |x| (safe), but a visited state (3.9, 3.1) is outside.
    # Bin (-1,0): corner (-1,0) is outside the wedge (bad), yet the state visited there is inside.
    # Bin (0,5): inside either way.
    trajs = [arr([(3.2, 3.5), (3.9, 3.1)]), arr([(-0.2, 0.5)]), arr([(0.5, 5.5)])]
    m = coverage_metrics(trajs, None, north, bin_rule="corner")
    assert (m["corner_n_bins"], m["corner_n_bad_bins"], m["corner_n_neutral_bins"]) == (3, 1, 2)
    assert (m["visited_n_bins"], m["visited_n_bad_bins"], m["visited_n_neutral_bins"]) == (3, 1, 2)
    # Same counts, different bins: the corner calls (-1,0) bad and (3,3) safe, visiting the reverse.
    only_33 = coverage_metrics([trajs[0]], None, north)
    assert (only_33["corner_n_bad_bins"], only_33["visited_n_bad_bins"]) == (0, 1)
    only_m10 = coverage_metrics([trajs[1]], None, north)
    assert (only_m10["corner_n_bad_bins"], only_m10["visited_n_bad_bins"]) == (1, 0)
    # The headline keys follow the chosen rule; the default is `visited`.
    assert m["safe_coverage"] == m["corner_safe_coverage"] == 2 - 1
    assert coverage_metrics([trajs[0]], None, north)["safe_coverage"] == only_33["visited_safe_coverage"] == -1
    assert coverage_metrics([trajs[0]], None, north, bin_rule="corner")["safe_ratio"] == 1.0
    with pytest.raises(ValueError, match="bin rule"):
        coverage_metrics(trajs, None, north, bin_rule="centre")


def test_corner_rule_good_class_and_one_dimensional_bins() -> None:
    # Range-North: the corners (0,10) and (-1,10) lie in the wedge and the disc -> good; the corner
    # (20,0) is 20.6 from the disc's centre (0,5) -> bad.
    m = coverage_metrics(
        [arr([(0.5, 10.5), (-0.5, 10.2), (20.5, 0.5)])], None, get_task("range_north"), bin_rule="corner"
    )
    assert (m["n_good_bins"], m["n_neutral_bins"], m["n_bad_bins"]) == (2, 0, 1)
    assert m["weighted_composite_coverage"] == 2 * 2 - 1
    # HalfCheetah Right: the bin [-1, 0) has corner −1 (bad) under both rules; the corner of [0, 1) is 0.
    x = np.array([-0.5, 0.5, 1.2, -1.5])
    c = coverage_metrics([x], None, get_task("right", "half_cheetah"), position_dims=1, bin_rule="corner")
    assert (c["n_bins"], c["n_bad_bins"], c["n_neutral_bins"]) == (4, 2, 2)


def test_corner_rule_on_a_pitch_task_counts_any_state_per_class() -> None:
    task = get_task("not_flip", "half_cheetah")
    x = np.array([0.2, 0.7, 1.5, 1.6])
    pitch = np.array([0.0, 2.0, 3.0, 3.0])  # bin 0: upright and flipped; bin 1: flipped only
    m = coverage_metrics([x], [pitch], task, position_dims=1)
    # visited: bin 0 bad (any bad), bin 1 bad.  corner (the reference's Not-Flip metric): bin 0 is
    # both safe and bad, bin 1 bad — a bin may count on both sides.
    assert (m["visited_n_bins"], m["visited_n_bad_bins"], m["visited_safe_ratio"]) == (2, 2, 0.0)
    assert (m["corner_n_bins"], m["corner_n_bad_bins"], m["corner_n_neutral_bins"]) == (2, 2, 1)
    assert m["corner_safe_coverage"] == 1 - 2 and m["corner_safe_ratio"] == 0.5


def test_travel_metrics_on_hand_built_paths() -> None:
    paths = [arr([(1.0, 1.0), (4.0, 5.0)]), arr([(0.0, 0.0), (-6.0, 8.0)]), arr([(0.0, 0.0), (0.0, 0.0)])]
    t = travel_metrics(paths)  # distances 5, 10, 0
    assert t == {"median_final_distance": 5.0, "max_final_distance": 10.0, "final_x_spread": 4.0 - (-6.0)}
    assert travel_metrics([np.array([0.0, 3.0]), np.array([0.0, -2.0])])["final_x_spread"] == 5.0  # 1-D paths


def test_the_curves_name_their_run_and_count_whole_epochs(tmp_path: pathlib.Path, monkeypatch) -> None:
    """Was: no title, and a two-evaluation run's axis read 0.2, 0.4, … epochs."""
    from matplotlib.figure import Figure

    saved: list[Figure] = []
    save = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: (saved.append(fig), save(fig, *a, **k))[1])
    records = [{"epoch": 0, "safe_ratio": 0.2}, {"epoch": 1, "safe_ratio": 0.5}]
    plots.plot_curves(records, ["safe_ratio"], tmp_path / "curves.png", "collie · point north · seed 0 · run")
    (fig,) = saved
    assert fig.get_suptitle() == "collie · point north · seed 0 · run"
    assert all(float(t).is_integer() for t in fig.axes[0].get_xticks())
