"""Physics overlapped with the policy (trainer/rollout.py): the same observations as serial
stepping for the same seeds and actions, on real MuJoCo, and deterministic runs per seed."""

import numpy as np
import pytest
import torch

from trainer.config import make_config
from trainer.envs import VectorEnv, make_env
from trainer.metra import Metra
from trainer.obs_noise import NoisyObservations
from trainer.rollout import Normaliser, rollout
from trainer.skills import SkillPrior

STEPS = 30


class RowPolicy:
    """A fixed nonlinear policy of each row's own state and skill, computed row by row (vectorised
    tanh rounds a batch's tail differently): actions do not depend on how the envs are grouped, so
    any difference would come from the stepping."""

    device = torch.device("cpu")

    def __init__(self, obs_dim: int, skill_dim: int, action_dim: int) -> None:
        g = torch.Generator().manual_seed(3)
        self.w = torch.randn(obs_dim, action_dim, generator=g)
        self.v = torch.randn(skill_dim, action_dim, generator=g)

    def act(self, obs: torch.Tensor, skill: torch.Tensor, deterministic: bool) -> torch.Tensor:
        rows = [torch.tanh(obs[i : i + 1].float() @ self.w + skill[i : i + 1] @ self.v) for i in range(len(obs))]
        return torch.cat(rows)


@pytest.mark.parametrize("name", ["point", "ant", "half_cheetah", "car"])
def test_overlapped_stepping_equals_serial_stepping(name: str) -> None:
    serial = VectorEnv(name, 5, episode_steps=STEPS, layout_seed=1, physics_threads=1)
    overlapped = VectorEnv(name, 5, episode_steps=STEPS, layout_seed=1, physics_threads=3)
    assert [g.stop - g.start for g in overlapped.groups] == [2, 1, 2]
    policy = RowPolicy(serial.obs_dim, 2, serial.action_dim)
    skills = np.random.default_rng(0).normal(size=(5, 2)).astype(np.float32)
    seeds = [5, 6, 7, 8, 9]
    norm = Normaliser(serial.obs_mean, serial.obs_std)

    # today's loop, written out: one policy call for all rows, then VectorEnv.step
    b = serial.reset(seeds)
    obs, qpos, xy = [b.obs.copy()], [b.qpos.copy()], [b.xy.copy()]
    for _ in range(STEPS):
        a = policy.act(torch.as_tensor(norm(b.obs)), torch.as_tensor(skills), True).numpy()
        b = serial.step(a)
        obs.append(b.obs.copy()), qpos.append(b.qpos.copy()), xy.append(b.xy.copy())

    traj = rollout(overlapped, policy, skills, seeds, norm, deterministic=True)  # type: ignore[arg-type]
    np.testing.assert_allclose(traj.obs, np.stack(obs, 1), rtol=0, atol=1e-6)
    np.testing.assert_allclose(traj.qpos, np.stack(qpos, 1).astype(np.float32), rtol=0, atol=1e-6)
    np.testing.assert_allclose(traj.xy, np.stack(xy, 1).astype(np.float32), rtol=0, atol=1e-6)
    assert not np.allclose(traj.obs[:, -1], traj.obs[:, 0])  # the envs did move
    overlapped.close()


def test_overlapped_rollouts_are_deterministic_per_seed() -> None:
    cfg = make_config("smoke", "ant")
    prior = SkillPrior(cfg.skill_dim, cfg.discrete_skills)
    env = VectorEnv("ant", 4, episode_steps=STEPS, physics_threads=2)
    agent = Metra(env.obs_dim, env.action_dim, prior, cfg, torch.device("cpu"))
    norm = Normaliser(env.obs_mean, env.obs_std)
    skills = prior.sample(4, np.random.default_rng(1))

    def run() -> np.ndarray:
        torch.manual_seed(11)  # the policy's sampling noise
        return rollout(env, agent, skills, [1, 2, 3, 4], norm, deterministic=False).obs

    np.testing.assert_array_equal(run(), run())
    env.close()


def test_physics_threads_must_be_positive() -> None:
    with pytest.raises(ValueError, match="physics_threads"):
        VectorEnv("point", 2, physics_threads=0)
    with pytest.raises(ValueError, match="batch_threads"):
        VectorEnv("point", 2, batch_threads=0)


@pytest.mark.parametrize("batch_threads", [1, 2])
@pytest.mark.parametrize("name", ["point", "ant", "half_cheetah"])
def test_batched_physics_equals_stepping_each_env(name: str, batch_threads: int) -> None:
    """A plain env's group steps as one mujoco.batch call (on 1 or 2 MuJoCo threads): bit-identical
    to each env's own step."""
    vec = VectorEnv(name, 4, episode_steps=STEPS, physics_threads=2, batch_threads=batch_threads)
    assert vec._physics is not None and vec._physics[0].batch.nthread == batch_threads  # the batched path
    singles = [make_env(name, episode_steps=STEPS) for _ in range(4)]
    seeds = [3, 4, 5, 6]
    b = vec.reset(seeds)
    first = [env.reset(seed=s) for env, s in zip(singles, seeds, strict=True)]
    np.testing.assert_array_equal(b.obs, np.stack([o for o, _ in first]))
    actions = np.random.default_rng(2).uniform(-1.2, 1.2, (STEPS, 4, vec.action_dim))  # beyond ctrlrange too
    for a in actions:
        b = vec.step(a)
        steps = [env.step(u) for env, u in zip(singles, a, strict=True)]
        np.testing.assert_array_equal(b.obs, np.stack([s[0] for s in steps]))
        np.testing.assert_array_equal(b.qpos, np.stack([s[4]["qpos"] for s in steps]))
        np.testing.assert_array_equal(b.qvel, np.stack([s[4]["qvel"] for s in steps]))
        np.testing.assert_array_equal(b.xy, np.stack([s[4]["xy"] for s in steps]))
        np.testing.assert_allclose(b.pitch, [s[4]["pitch"] for s in steps], rtol=0, atol=1e-12)
    assert vec.truncated and singles[0].t == STEPS
    with pytest.raises(RuntimeError, match="episode over"):
        vec.step(actions[0])
    vec.close()


def test_rollouts_keep_what_a_wrapper_observes() -> None:
    """A wrapper that replaces the step's observations (NoisyObservations) has them stored, while
    the rollout's own arrays take every other field straight from the physics."""
    env = VectorEnv("half_cheetah", 4, episode_steps=STEPS)
    noisy = NoisyObservations(env, 0.1)
    policy = RowPolicy(env.obs_dim, 2, env.action_dim)
    skills = np.random.default_rng(0).normal(size=(4, 2)).astype(np.float32)
    norm = Normaliser(env.obs_mean, env.obs_std)
    traj = rollout(noisy, policy, skills, [1, 2, 3, 4], norm, deterministic=True)  # type: ignore[arg-type]
    exact = np.concatenate([traj.qpos, traj.qvel], -1)  # HalfCheetah observes [qpos, qvel]
    ratio = traj.obs / np.where(exact == 0, 1, exact)
    assert 0.05 < ratio[:, 1:].std() < 0.2  # every stored step is (1 + 0.1·x)·s, not s itself
    env.close()
