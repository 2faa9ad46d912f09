"""The Safety-Gym-style car: hazard layout from the experiment seed, lidar, the Hazard rule and its
0.01 × 0.01 coverage bins, the scene a viewer rebuilds, and a smoke training run."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

import trainer.loop
from collie.tasks import BAD, NEUTRAL, get_task, hazard_layout
from trainer.config import make_config
from trainer.envs import load_model, make_env, model_xml
from trainer.envs.lidar import pseudo_lidar
from trainer.metrics import coverage_metrics

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)


def test_layout_is_reproducible_from_the_seed_and_well_placed() -> None:
    a = hazard_layout(7)
    np.testing.assert_array_equal(a, hazard_layout(7))
    assert not np.allclose(a, hazard_layout(8))
    assert a.shape == (8, 2) and np.abs(a).max() <= 1.5 - 0.2  # every disc inside ±1.5
    gaps = np.hypot(*(a[:, None] - a[None]).transpose(2, 0, 1))[np.triu_indices(8, 1)]
    assert gaps.min() >= 0.4 and np.hypot(*a.T).min() >= 0.35  # no overlap; the start is clear


def test_env_task_and_scene_share_the_layout() -> None:
    env = make_env("car", seed=0, layout_seed=3)
    task = get_task("hazard", "car", layout_seed=3)
    centres = np.array([r.centre for r in task.regions])
    np.testing.assert_allclose(env.hazards, centres)
    model = load_model("car", layout_seed=3)
    drawn = model.geom_pos[[model.geom(f"hazard{i}").id for i in range(8)], :2]
    np.testing.assert_allclose(drawn, centres, atol=1e-5)  # MJCF text keeps 6 significant digits
    assert (model.geom_contype[model.geom("hazard0").id], model.geom_conaffinity[model.geom("hazard0").id]) == (0, 0)
    assert (model.nq, model.nv, model.nu) == (env.nq, env.nv, env.action_dim) == (9, 8, 2)
    bare = mujoco.MjModel.from_xml_string(model_xml("car"))
    assert bare.ngeom == model.ngeom - 8
    assert mujoco.MjModel.from_xml_string(model_xml("car", layout_seed=3)).ngeom == model.ngeom


def test_hazard_rule_and_its_drawing() -> None:
    task = get_task("hazard", "car", layout_seed=0)
    (cx, cy) = task.regions[0].centre
    points = np.array([[cx, cy], [cx + 0.19, cy], [cx, cy - 0.199], [cx + 0.21, cy], [5.0, 5.0]])
    assert task.classify(points).tolist() == [BAD, BAD, BAD, NEUTRAL, NEUTRAL]
    d = task.to_dict()
    assert d["background"] == NEUTRAL and len(d["regions"]) == 8
    assert d["regions"][0] == {"kind": "disc", "desirability": BAD, "centre": [cx, cy], "radius": 0.2}
    with pytest.raises(ValueError, match="layout_seed"):
        get_task("hazard", "car")
    with pytest.raises(ValueError, match="car"):
        get_task("hazard", "ant", layout_seed=0)


def test_coverage_bins_are_a_centimetre() -> None:
    task = get_task("hazard", "car", layout_seed=0)
    cx, cy = task.regions[0].centre
    xs = (np.floor(cx / 0.01) + np.arange(-30, 31) + 0.5) * 0.01  # bin centres on a line through the hazard
    path = np.stack([xs, np.full_like(xs, (np.floor(cy / 0.01) + 0.5) * 0.01)], axis=1)
    inside = int((np.hypot(path[:, 0] - cx, path[:, 1] - cy) < 0.2).sum())
    m = coverage_metrics([path], None, task, bin_size=make_env("car").metric_bin_size)
    assert (m["n_bins"], m["n_bad_bins"]) == (61, inside) and 35 <= inside <= 40
    assert m["safe_coverage"] == 61 - 2 * inside


def test_lidar_sees_hazards_in_the_right_bins() -> None:
    objects = np.array([[1.0, 0.0], [0.0, -2.0], [1.0, 0.05]])
    reading = pseudo_lidar(np.zeros(2), 0.0, objects)
    assert reading.shape == (16,) and reading[0] == pytest.approx(math.exp(-1.0))  # ahead: the nearer one
    assert reading[12] == pytest.approx(math.exp(-2.0))  # 270° anticlockwise = right-hand side
    assert np.count_nonzero(reading) == 2
    turned = pseudo_lidar(np.zeros(2), math.pi / 2, objects)  # facing +y: the object at +x is to the right
    assert turned[12] == pytest.approx(math.exp(-1.0)) and turned[8] == pytest.approx(math.exp(-2.0))


def test_car_drives_and_observes_itself() -> None:
    env = make_env("car", seed=0, layout_seed=1)
    obs, info = env.reset()
    assert obs.shape == (25,) and obs.dtype == np.float32 and env.obs_shape == (25,)
    np.testing.assert_allclose(obs[:2], info["xy"], atol=1e-6)
    assert np.hypot(*info["xy"]) <= 0.03 and obs[2] ** 2 + obs[3] ** 2 == pytest.approx(1.0, abs=1e-6)
    heading = math.atan2(obs[3], obs[2])
    for _ in range(100):
        obs, _, _, _, info = env.step(np.ones(2))
    travel = info["xy"]  # straight ahead, along the initial heading
    assert np.hypot(*travel) > 1.0
    assert abs(math.remainder(math.atan2(travel[1], travel[0]) - heading, 2 * math.pi)) < 0.05
    assert obs[7] > 10 and obs[8] > 10  # both wheels spinning forward
    assert np.count_nonzero(obs[9:]) > 0 and obs[9:].max() <= 1.0


def test_smoke_training_on_the_car(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[float] = []

    def spy(*args, **kwargs):
        seen.append(kwargs["bin_size"])
        return coverage_metrics(*args, **kwargs)

    monkeypatch.setattr(trainer.loop, "coverage_metrics", spy)
    cfg = make_config("smoke", "car", task="hazard", seed=4, out=str(tmp_path))
    t = trainer.loop.Trainer(cfg, progress=False)
    np.testing.assert_allclose(t.env.envs[0].hazards, hazard_layout(4))  # the run's seed places the hazards
    summary = t.run()
    assert summary["status"] == "finished" and summary["n_labels"] == 6 and seen and set(seen) == {0.01}
