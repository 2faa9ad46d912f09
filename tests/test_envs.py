"""The environments with real MuJoCo: shapes, positions, pitch, determinism, episode length."""

from __future__ import annotations

import math
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest

import collie.env_names
from trainer.envs import ENV_NAMES, StepBatch, VectorEnv, load_model, make_env, model_path, raw_step_rate
from trainer.envs.ant import quat_pitch

# State envs: obs_dim, action_dim, nq. The pixel envs have their own tests (tests/test_pixel_envs.py).
DIMS = {"point": (4, 2, 2), "ant": (29, 8, 15), "half_cheetah": (18, 6, 9), "car": (25, 2, 9)}
PIXEL_ENVS = {"quadruped", "humanoid"}


def test_env_names() -> None:
    assert set(ENV_NAMES) == set(DIMS) | PIXEL_ENVS
    assert collie.env_names.PIXEL_ENVS == PIXEL_ENVS  # what the config refuses state-only methods on
    assert ENV_NAMES == collie.env_names.ENV_NAMES  # the names the service takes runs of, and the UI replays


def test_the_services_joint_table_is_the_models() -> None:
    """The service refuses a run whose dims are not its env's by this table (it imports no MuJoCo)."""
    assert {name: (load_model(name).nq, load_model(name).nv) for name in ENV_NAMES} == collie.env_names.ENV_JOINTS


@pytest.mark.parametrize("name", DIMS)
def test_reset_and_step_shapes(name: str) -> None:
    obs_dim, action_dim, nq = DIMS[name]
    env = make_env(name, seed=0)
    assert (env.name, env.obs_dim, env.action_dim, env.nq) == (name, obs_dim, action_dim, nq)
    obs, info = env.reset()
    assert obs.shape == (obs_dim,) and obs.dtype == np.float32
    assert info["xy"].shape == (2,) and info["xy"].dtype == np.float64
    assert info["qpos"].shape == (env.nq,) and info["qvel"].shape == (env.nv,)
    obs, reward, terminated, truncated, info = env.step(np.zeros(action_dim))
    assert obs.shape == (obs_dim,) and obs.dtype == np.float32
    assert (reward, terminated, truncated) == (0.0, False, False)
    assert isinstance(info["pitch"], float)
    info["qpos"][:] = 1e6  # a copy: editing it must not touch the simulation
    assert not np.any(env.data.qpos == 1e6)


@pytest.mark.parametrize("name", DIMS)
def test_normaliser_stats_finite_and_positive(name: str) -> None:
    env = make_env(name)
    assert env.obs_mean.shape == env.obs_std.shape == (env.obs_dim,)
    assert np.all(np.isfinite(env.obs_mean)) and np.all(np.isfinite(env.obs_std))
    assert np.all(env.obs_std >= 1e-3)


@pytest.mark.parametrize("name", DIMS)
def test_model_path_rebuilds_the_same_model(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    env = make_env(name)
    model = load_model(name)
    assert model_path(name).is_file()
    assert (model.nq, model.nv, model.nu) == (env.nq, env.nv, env.action_dim)
    np.testing.assert_array_equal(model.body_mass, env.model.body_mass)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()  # no deprecation log dropped in the cwd


def test_truncated_exactly_at_episode_steps() -> None:
    env = make_env("point", seed=0, episode_steps=5)
    env.reset()
    flags = [env.step(np.zeros(2))[3] for _ in range(5)]
    assert flags == [False] * 4 + [True]
    with pytest.raises(RuntimeError):
        env.step(np.zeros(2))
    env.reset()
    assert env.step(np.zeros(2))[3] is False


def test_point_travels_fast_in_a_straight_line() -> None:
    env = make_env("point", seed=0)
    _, info = env.reset()
    start = info["xy"]
    for _ in range(200):
        obs, *_, truncated, info = env.step(np.array([1.0, 0.0]))
    assert truncated
    assert info["xy"][0] - start[0] >= 40.0
    assert abs(info["xy"][1] - start[1]) < 1e-9
    assert math.isnan(info["pitch"])
    np.testing.assert_allclose(obs[:2], info["xy"], rtol=1e-6)
    # Out-of-range actions are clamped by MuJoCo's ctrlrange, not amplified.
    env.reset(seed=0)
    for _ in range(10):
        env.step(np.array([5.0, 0.0]))
    assert env.data.qvel[0] <= 5.0 + 1e-9


def test_ant_obs_starts_with_xy_and_matches_gymnasium() -> None:
    import gymnasium as gym

    env = make_env("ant", seed=3)
    ref = gym.make(
        "Ant-v5",
        exclude_current_positions_from_observation=False,
        include_cfrc_ext_in_observation=False,
        terminate_when_unhealthy=False,
    )
    obs, info = env.reset()
    ref_obs, _ = ref.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(30):
        np.testing.assert_allclose(obs, ref_obs.astype(np.float32))
        np.testing.assert_allclose(obs[:2], info["xy"], rtol=1e-6)
        action = rng.uniform(-1, 1, 8)
        obs, _, _, _, info = env.step(action)
        ref_obs = ref.step(action)[0]
    quat = env.data.qpos[3:7] / np.linalg.norm(env.data.qpos[3:7])
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, quat)  # torso orientation as MuJoCo computes it
    rot = rot.reshape(3, 3)
    assert info["pitch"] == pytest.approx(math.atan2(-rot[2, 0], rot[2, 2]), abs=1e-6)


def test_half_cheetah_is_one_dimensional_and_pitches() -> None:
    env = make_env("half_cheetah", seed=0)
    _, info = env.reset()
    pitches = []
    rng = np.random.default_rng(0)
    for _ in range(100):
        _, _, _, _, info = env.step(rng.uniform(-1, 1, 6))
        assert info["xy"][1] == 0.0 and info["xy"][0] == info["qpos"][0]
        pitches.append(info["pitch"])
    assert np.ptp(pitches) > 0.05  # random flailing rocks the body
    assert all(-math.pi <= p < math.pi for p in pitches)


def test_quat_pitch() -> None:
    for angle in (0.0, 0.3, -1.2, 2.5):
        w, y = math.cos(angle / 2), math.sin(angle / 2)
        assert quat_pitch(2 * w, 0.0, 2 * y, 0.0) == pytest.approx(angle)  # scale-free
    assert abs(quat_pitch(0.0, 1.0, 0.0, 0.0)) == pytest.approx(math.pi)  # rolled onto its back


@pytest.mark.parametrize("name", ["point", "ant"])
def test_vector_env_is_deterministic(name: str) -> None:
    def rollout() -> list[StepBatch]:
        vec = VectorEnv(name, num_envs=3, episode_steps=10)
        actions = np.random.default_rng(7).uniform(-1, 1, (10, 3, vec.action_dim))
        return [vec.reset([11, 12, 13])] + [vec.step(a) for a in actions]

    first, second = rollout(), rollout()
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.obs, b.obs)
        np.testing.assert_array_equal(a.qpos, b.qpos)
    assert not np.array_equal(first[-1].obs[0], first[-1].obs[1])  # different seeds, different states


def test_vector_env_batch_shapes_and_episode_end() -> None:
    vec = VectorEnv("half_cheetah", num_envs=4, episode_steps=3)
    assert (vec.num_envs, vec.obs_dim, vec.action_dim, vec.position_dims) == (4, 18, 6, 1)
    batch = vec.reset(range(4))
    for _ in range(3):
        batch = vec.step(np.zeros((4, 6)), out=batch)
    assert vec.truncated
    assert batch.obs.shape == (4, 18) and batch.obs.dtype == np.float32
    assert batch.xy.shape == (4, 2) and batch.xy.dtype == np.float64
    assert batch.pitch.shape == (4,) and batch.qpos.shape == (4, vec.nq) and batch.qvel.shape == (4, vec.nv)
    np.testing.assert_array_equal(batch.xy[:, 1], 0.0)
    np.testing.assert_array_equal(batch.xy[:, 0], batch.qpos[:, 0])
    with pytest.raises(RuntimeError):
        vec.step(np.zeros((4, 6)))
    with pytest.raises(ValueError):
        vec.reset([0, 1])


def test_unknown_name_lists_valid_names() -> None:
    with pytest.raises(ValueError) as err:
        make_env("walker")
    for name in ENV_NAMES:
        assert name in str(err.value)


def test_raw_step_rate_counts_every_step_it_times(monkeypatch: pytest.MonkeyPatch) -> None:
    """300 steps through the env's own `step`, and a rate no lower than 300 over the whole call."""
    calls = []

    def counted(name: str, seed: int = 0) -> object:
        env = make_env(name, seed=seed)
        step = env.step
        env.step = lambda action: calls.append(action) or step(action)  # type: ignore[method-assign]
        return env

    monkeypatch.setattr("trainer.envs.rate.make_env", counted)
    start = time.perf_counter()
    rate = raw_step_rate("point", steps=300)
    wall = time.perf_counter() - start
    assert len(calls) == 300
    assert 300 / wall <= rate < math.inf  # the timed part is within the call
