"""Task rules at and around every boundary, env geometry, regions JSON and the registry."""

from __future__ import annotations

import json
import math
import pathlib
import re
from collections.abc import Iterator

import numpy as np
import pytest

from collie.env_names import ENV_NAMES
from collie.tasks import BAD, GOOD, NEUTRAL, TASK_NAMES, Disc, Task, default_task, get_task, task_names
from collie.tasks import registry as task_registry

EPS = 1e-6
DOCS = pathlib.Path(__file__).resolve().parents[1] / "docs" / "tasks.md"


def classify(name: str, points: list[tuple[float, float]], env: str = "point") -> list[int]:
    return get_task(name, env).classify(np.array(points, dtype=float)).tolist()


def test_builtin_names_are_registered() -> None:
    assert TASK_NAMES == ("north", "right", "range", "hole", "not_flip", "range_north", "hole_north")
    assert set(TASK_NAMES) <= set(task_names())


def test_north_boundary() -> None:
    on = [(0, 0), (5, 5), (-5, 5)]
    inside = [(0, EPS), (5, 5 + EPS), (-5, 5 + EPS), (0, 30)]
    outside = [(0, -EPS), (5, 5 - EPS), (-5, 5 - EPS), (30, 0), (0, -30)]
    assert classify("north", on + inside) == [NEUTRAL] * 7
    assert classify("north", outside) == [BAD] * 5


def test_right_boundary() -> None:
    assert classify("right", [(0, 0), (0, -7), (EPS, 3), (-EPS, 3), (-40, 0)]) == [
        NEUTRAL, NEUTRAL, NEUTRAL, BAD, BAD,
    ]  # fmt: skip


def test_range_boundary_circle() -> None:
    on = [(0, 25), (0, -15), (20, 5), (-20, 5), (12, 21)]  # centre (0, 5), r 20 (12-16-20)
    assert classify("range", on) == [NEUTRAL] * 5
    assert classify("range", [(0, 25 - EPS), (0, 5)]) == [NEUTRAL] * 2
    assert classify("range", [(0, 25 + EPS), (20 + EPS, 5), (0, -15 - EPS)]) == [BAD] * 3


def test_hole_circles() -> None:
    for cx, cy in [(0, 20), (0, -20), (20, 0), (-20, 0)]:
        on = [(cx + 12, cy), (cx - 12, cy), (cx, cy + 12), (cx, cy - 12)]
        assert classify("hole", on) == [NEUTRAL] * 4
        assert classify("hole", [(cx, cy), (cx + 12 - EPS, cy)]) == [BAD, BAD]
        assert classify("hole", [(cx + 12 + EPS, cy)]) == [NEUTRAL]
    assert classify("hole", [(0, 0), (30, 30)]) == [NEUTRAL, NEUTRAL]


def test_not_flip_pitch() -> None:
    task = get_task("not_flip", "half_cheetah")
    xy = np.zeros((8, 2))
    half = math.pi / 2
    pitch = np.array([0, half, -half, half + EPS, -half - EPS, math.pi, 2 * math.pi, 2 * math.pi + half + 0.1])
    assert task.classify(xy, pitch).tolist() == [NEUTRAL] * 3 + [BAD] * 3 + [NEUTRAL, BAD]
    far = np.array([[1e3, -1e3]])
    assert task.classify(far, np.array([0.0])).tolist() == [NEUTRAL]  # position ignored
    assert task.classify(np.zeros((1, 2)), np.array([np.nan])).tolist() == [NEUTRAL]
    with pytest.raises(ValueError, match="pitch"):
        task.classify(xy)


def test_range_north_classes() -> None:
    assert classify("range_north", [(0, 10), (0, 25), (0, 0), (3, 3)]) == [GOOD] * 4
    assert classify("range_north", [(10, 0), (3, 3 - EPS), (-10, 2)]) == [NEUTRAL] * 3
    assert classify("range_north", [(0, 25 + EPS), (30, 0), (0, 40)]) == [BAD] * 3


def test_hole_north_classes() -> None:
    # holes (±15, ±15) r 12: the hole (15, 15) reaches into the wedge
    assert classify("hole_north", [(0, 10), (15, 27), (3, 15), (0, 0)]) == [GOOD] * 4
    assert classify("hole_north", [(15, 15), (15, 27 - EPS), (-15, -15), (15, -15)]) == [BAD] * 4
    assert classify("hole_north", [(10, 0), (0, -10), (15, 27 + EPS)]) == [NEUTRAL, NEUTRAL, GOOD]


def test_single_constraint_tasks_never_good() -> None:
    grid = np.stack(np.meshgrid(np.linspace(-40, 40, 41), np.linspace(-40, 40, 41)), -1).reshape(-1, 2)
    pitch = np.linspace(-4, 4, len(grid))
    for name in ("north", "right", "range", "hole", "not_flip"):
        task = get_task(name, "ant")
        assert not task.can_be_good
        assert GOOD not in task.classify(grid, pitch)
    for name in ("range_north", "hole_north"):
        assert get_task(name).can_be_good
        assert GOOD in get_task(name).classify(grid)


def test_env_dependent_geometry() -> None:
    for env in ("quadruped", "humanoid"):
        assert classify("range", [(0, 10), (0, 10 + EPS), (8, 2)], env) == [NEUTRAL, BAD, NEUTRAL]
        assert classify("hole", [(0, 8), (0, 4), (0, 4 + EPS), (12, 0)], env) == [BAD, NEUTRAL, BAD, NEUTRAL]
        assert classify("hole_north", [(6, 6), (6, 10), (0, 5)], env) == [BAD, GOOD, GOOD]
    assert classify("range", [(0, 10 + EPS)], "ant") == [NEUTRAL]  # Ant disc is much larger
    assert classify("hole", [(0, 14)], "ant") == [BAD]
    assert classify("hole", [(0, 14)], "humanoid") == [NEUTRAL]
    with pytest.raises(ValueError, match="humanoid"):
        get_task("range", "walker")


def test_boundary_distance() -> None:
    pts = np.array([[0.0, 0.0], [0.0, 10.0], [3.0, -4.0], [10.0, 0.0]])
    s2 = math.sqrt(2)
    assert np.allclose(get_task("north").boundary_distance(pts), [0, 10 / s2, 5, 10 / s2])
    assert np.allclose(get_task("right").boundary_distance(pts), [0, 0, 3, 10])
    assert np.allclose(
        get_task("range").boundary_distance(pts), [15, 15, 20 - math.hypot(3, 9), 20 - math.hypot(10, 5)]
    )
    assert np.allclose(get_task("hole").boundary_distance(pts), [8, 2, math.hypot(3, 16) - 12, 2])
    # the good/neutral edge y = |x| is not a safety boundary: range_north = range's circle
    assert np.allclose(get_task("range_north").boundary_distance(pts), get_task("range").boundary_distance(pts))
    pitch = np.array([0.0, math.pi / 2, 2.0, -math.pi])
    assert np.allclose(
        get_task("not_flip", "ant").boundary_distance(pts, pitch), [math.pi / 2, 0, 2 - math.pi / 2, math.pi / 2]
    )


def test_to_dict_is_json_and_describes_regions() -> None:
    for name in TASK_NAMES:
        d = json.loads(json.dumps(get_task(name, "ant").to_dict()))
        assert d["name"] == name and d["description"] and set(d["meaning"]) == {"0", "1", "2"}
    d = get_task("range_north").to_dict()
    assert d["background"] == NEUTRAL and d["can_be_good"]
    assert d["regions"] == [
        {"kind": "wedge_north", "desirability": GOOD, "apex": [0.0, 0.0]},
        {"kind": "outside_disc", "desirability": BAD, "centre": [0.0, 5.0], "radius": 20.0},
    ]
    assert get_task("right").to_dict()["regions"][0]["kind"] == "halfplane_left"
    assert get_task("not_flip", "ant").to_dict()["uses_pitch"]


def test_not_flip_needs_a_body_that_can_tip_over() -> None:
    with pytest.raises(ValueError, match="not defined for env 'point'") as err:
        get_task("not_flip", "point")  # its pitch is undefined: every state would be neutral
    assert "half_cheetah" in str(err.value) and "not_flip" not in task_registry.tasks_for("point")


def test_half_cheetah_has_only_the_tasks_of_a_body_on_a_line() -> None:
    """Its y is always 0: the paper defines Right and Not-Flip for it, and a wedge or disc in x-y would
    judge a line through the plane (North: every x but 0 bad)."""
    built_in = [t for t in task_registry.tasks_for("half_cheetah") if t in TASK_NAMES]  # other tests register more
    assert built_in == ["right", "not_flip"]
    with pytest.raises(ValueError, match="task 'north' is not defined for env 'half_cheetah'") as err:
        get_task("north", "half_cheetah")
    assert "half_cheetah's tasks: right, not_flip" in str(err.value)
    with pytest.raises(ValueError, match=r"not defined for env 'car' \(only for point, ant, quadruped, humanoid\)"):
        get_task("north", "car")
    assert [default_task(env) for env in ("point", "ant", "half_cheetah", "humanoid", "car")] == [
        "north", "north", "right", "north", "hazard"
    ]  # fmt: skip
    assert all(default_task(env) in task_registry.tasks_for(env) for env in ENV_NAMES)


def test_unknown_task_lists_valid_names() -> None:
    with pytest.raises(ValueError) as err:
        get_task("south")
    assert "south" in str(err.value)
    assert all(name in str(err.value) for name in TASK_NAMES)


@pytest.mark.parametrize(("task", "env", "theirs"), [("north", "car", "hazard"), ("hazard", "point", "north")])
def test_a_task_on_an_env_it_is_not_defined_for_lists_that_envs_tasks(task: str, env: str, theirs: str) -> None:
    with pytest.raises(ValueError) as err:
        get_task(task, env, layout_seed=0)
    assert f"task {task!r} is not defined for env {env!r}" in str(err.value)
    assert f"{env}'s tasks: " in str(err.value) and theirs in str(err.value) and "unknown env" not in str(err.value)


def test_bad_inputs_rejected() -> None:
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        get_task("north").classify(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="desirability"):
        Disc((0.0, 0.0), 1.0, desirability=3)
    with pytest.raises(ValueError, match="radius"):
        Disc((0.0, 0.0), 0.0, desirability=BAD)


@pytest.fixture
def clean_registry() -> Iterator[None]:
    before = dict(task_registry._FACTORIES)
    yield
    task_registry._FACTORIES.clear()
    task_registry._FACTORIES.update(before)


def test_docs_examples_register_usable_tasks(clean_registry: None) -> None:
    section = DOCS.read_text().split("## How to add a task", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(blocks) == 2
    for block in blocks:
        exec(compile(block, str(DOCS), "exec"), {})
    assert {"pond", "east"} <= set(task_names())
    pond = get_task("pond", "ant")
    assert pond.classify(np.array([[10.0, 0.0], [15.0, 0.0], [0.0, 0.0]])).tolist() == [BAD, NEUTRAL, NEUTRAL]
    assert np.allclose(pond.boundary_distance(np.array([[0.0, 0.0]])), [5.0])
    assert pond.to_dict()["regions"][0]["kind"] == "disc"
    east = get_task("east")
    assert east.classify(np.array([[3.0, 0.0], [2.9, 9.0]])).tolist() == [NEUTRAL, BAD]
    with pytest.raises(NotImplementedError, match="distance"):
        east.boundary_distance(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="already registered"):
        exec(compile(blocks[0], str(DOCS), "exec"), {})


def test_rule_output_is_validated(clean_registry: None) -> None:
    task = Task("broken", "returns 3", rule=lambda xy, pitch: np.full(len(xy), 3))
    with pytest.raises(ValueError, match="rule must return"):
        task.classify(np.zeros((2, 2)))
