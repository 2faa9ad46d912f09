"""Observation statistics: METRA's fixed presets (`--obs-norm reference`) against our own rollouts
(`--obs-norm rollout`), the normaliser on hand-built states, and which one a run gets."""

from __future__ import annotations

import numpy as np
import pytest

from trainer.config import Config, make_config
from trainer.envs import make_env
from trainer.envs.normalizer import STD_FLOOR, random_rollout_stats
from trainer.obs_stats import REFERENCE_STATS, observation_stats
from trainer.rollout import Normaliser


@pytest.mark.parametrize("name", ["ant", "half_cheetah"])
def test_reference_stats_fit_our_observation_layout(name: str) -> None:
    env = make_env(name)
    mean, std = REFERENCE_STATS[name]
    assert mean.shape == std.shape == (env.obs_dim,)
    assert np.all(std > 0) and np.all(np.isfinite(mean))
    # Same layout as ours ([qpos, qvel], root position kept): the velocity block's spread agrees
    # with our own random rollouts within a third, dimension by dimension.
    vel = slice(env.nq, env.obs_dim)
    np.testing.assert_allclose(std[vel], env.obs_std[vel], rtol=0.35)
    with pytest.raises(ValueError):
        mean[0] = 1.0  # shared constants are read-only


def test_reference_ant_positions_and_joints() -> None:
    mean, std = REFERENCE_STATS["ant"]
    assert std[0] == pytest.approx(0.6247, abs=1e-4) and std[1] == pytest.approx(0.6196, abs=1e-4)
    ours = make_env("ant").obs_std
    assert ours[0] > 2 * std[0]  # 200-step rollouts spread x-y wider than the reference's 50-step ones
    # Ankles (qpos 8, 10, 12, 14) rest at ±0.86 rad with alternating signs, as in our rollouts.
    ankles = [8, 10, 12, 14]
    np.testing.assert_allclose(mean[ankles], [0.86, -0.86, -0.86, 0.86], atol=0.01)
    np.testing.assert_allclose(np.sign(make_env("ant").obs_mean[ankles]), np.sign(mean[ankles]))


def test_normaliser_on_hand_built_states() -> None:
    mean, std = REFERENCE_STATS["ant"]
    state = mean + 2.0 * std  # two standard deviations above the mean in every dimension
    state[0] = mean[0] + 6.0 * std[0]
    out = Normaliser(mean, std)(np.stack([mean, state]))
    np.testing.assert_allclose(out[0], 0.0, atol=1e-6)
    np.testing.assert_allclose(out[1, 1:], 2.0, rtol=1e-5)
    assert out[1, 0] == pytest.approx(6.0, rel=1e-5)
    # One metre east is 1/0.62 ≈ 1.6 units with the reference's statistics, 1/1.6 ≈ 0.6 with ours.
    env = make_env("ant")
    east = np.zeros((2, 29), np.float32)
    east[1, 0] = 1.0
    ref = Normaliser(mean, std)(east)
    rollout = Normaliser(env.obs_mean, env.obs_std)(east)
    assert ref[1, 0] - ref[0, 0] == pytest.approx(1 / 0.62473416, rel=1e-5)
    assert rollout[1, 0] - rollout[0, 0] < 0.7


def test_random_rollout_stats_match_a_plain_computation() -> None:
    mean, std = random_rollout_stats("point", episodes=3, episode_steps=5)
    env = make_env("point", episode_steps=5)
    rng = np.random.default_rng(0)
    states = []
    for ep in range(3):
        states.append(env.reset(seed=ep)[0])
        for _ in range(5):
            states.append(env.step(rng.uniform(-1.0, 1.0, env.action_dim))[0])
    states = np.array(states, dtype=float)
    np.testing.assert_allclose(mean, states.mean(axis=0), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(std, np.maximum(states.std(axis=0), STD_FLOOR), rtol=1e-6)


def test_which_statistics_a_run_gets() -> None:
    assert make_config("cpu", "ant").obs_norm == "reference"
    assert make_config("paper", "half_cheetah").obs_norm == "reference"
    assert make_config("cpu", "point").obs_norm == "rollout"
    assert make_config("cpu", "ant", obs_norm="rollout").obs_norm == "rollout"
    with pytest.raises(ValueError, match="only for ant, half_cheetah"):
        make_config("cpu", "point", obs_norm="reference")
    with pytest.raises(ValueError, match="obs_norm"):
        make_config("cpu", "ant", obs_norm="running")
    env = make_env("half_cheetah")
    m, s = observation_stats("half_cheetah", env.obs_mean, env.obs_std, "reference")
    assert m is REFERENCE_STATS["half_cheetah"][0] and s is REFERENCE_STATS["half_cheetah"][1]
    m, s = observation_stats("half_cheetah", env.obs_mean, env.obs_std, "rollout")
    assert m is env.obs_mean and s is env.obs_std


def test_a_saved_run_from_before_these_options_keeps_what_it_ran_with() -> None:
    saved = make_config("cpu", "ant").to_dict()
    assert Config.from_stored(saved) == make_config("cpu", "ant")
    for key in ("init", "log_std_min", "diayn", "obs_norm", "bin_rule", "fused_adam", "fast_ops"):
        saved.pop(key)
    old = Config.from_stored({**saved, "a_key_from_the_future": 1})
    assert (old.obs_norm, old.init, old.log_std_min, old.diayn) == ("rollout", "torch", -5.0, "sphere")
    assert not old.fused_adam and not old.fast_ops  # a resumed old run keeps its step's arithmetic


def test_a_saved_run_without_acting_is_dated_by_its_keys() -> None:
    """Rollouts acted through `Actor` ("fast") from 12-01 16:07, but `acting` entered the config
    only on 12-05: before then a config shows the fast path by holding `physics_threads` (16:48).
    A run from before acted through torch; resumed fast, its next epochs differed from the old
    code's continuation (and a report took it for today's runs)."""
    from trainer.same_run import differing_keys

    today = make_config("cpu", "point").to_dict()
    fast = {k: v for k, v in today.items() if k != "acting"}  # 12-01 17:00 to 12-05
    torch_era = {k: v for k, v in fast.items() if k != "physics_threads"}  # before 12-01 16:07
    assert Config.from_stored(fast).acting == "fast" and Config.from_stored(torch_era).acting == "torch"
    assert differing_keys(torch_era, today) == ["acting"]  # was []: averaged with today's runs
    assert differing_keys(torch_era, {**today, "acting": "torch"}) == []  # what reproduces it
    assert differing_keys(fast, today) == []
