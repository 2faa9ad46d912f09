"""The rollout's acting path (trainer/acting.py) gives the policy's own actions: for the same
observations, skills and torch seed (the same noise draw) `Actor` equals TanhGaussianPolicy.act
on normalised inputs, for whole batches and for row groups, sampled and deterministic; `Actor`
and the rollout loop are bit-identical to their arithmetic written out plainly."""

import numpy as np
import pytest
import torch

from trainer.acting import PATHS, Actor, TorchActor, acting_path, actor, fits
from trainer.config import ACTING_PATHS, make_config
from trainer.envs import VectorEnv, make_env
from trainer.metra import Metra
from trainer.networks import LOG_STD_MAX
from trainer.rollout import Normaliser, rollout
from trainer.skills import SkillPrior

GROUPS = (slice(0, 3), slice(3, 8))  # row groups as a pipelined rollout acts them


def setup(env_name: str, preset: str = "cpu") -> tuple[Metra, np.ndarray, np.ndarray, Normaliser]:
    env = make_env(env_name)
    cfg = make_config(preset, env_name)
    prior = SkillPrior(cfg.skill_dim, cfg.discrete_skills)
    agent = Metra(env.obs_dim, env.action_dim, prior, cfg, torch.device("cpu"))
    rng = np.random.default_rng(0)
    with torch.no_grad():  # trained-looking weights: non-zero biases, larger log-stds
        for p in agent.policy.parameters():
            p.add_(0.02 * torch.randn_like(p))
    obs = (env.obs_mean + env.obs_std * rng.normal(size=(8, env.obs_dim))).astype(np.float32)
    return agent, obs, prior.sample(8, rng), Normaliser(env.obs_mean, env.obs_std)


def reference(agent: Metra, obs: np.ndarray, skills: np.ndarray, norm: Normaliser, det: bool) -> np.ndarray:
    return agent.act(torch.as_tensor(norm(obs)), torch.as_tensor(skills), det).numpy()


@pytest.mark.parametrize("env_name", ["ant", "half_cheetah", "point"])
@pytest.mark.parametrize("deterministic", [False, True])
def test_actor_equals_the_policy_forward(env_name: str, deterministic: bool) -> None:
    agent, obs, skills, norm = setup(env_name)
    assert fits(agent)
    fast = Actor(agent, skills, norm, deterministic)
    for seed in range(3):
        torch.manual_seed(seed)
        want = reference(agent, obs, skills, norm, deterministic)
        torch.manual_seed(seed)
        got = np.empty_like(want)
        fast(obs, slice(None), got)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)
        assert np.abs(got).max() <= 1 and np.ptp(got) > 0.1  # real actions, not a constant
        obs = obs + 0.5  # a new step through the same buffers


def test_actor_rows_draw_the_noise_per_call() -> None:
    """The pipeline acts per group of rows; each call draws that group's noise, as the policy would."""
    agent, obs, skills, norm = setup("ant")
    fast = Actor(agent, skills, norm, deterministic=False)
    torch.manual_seed(4)
    want = np.concatenate([reference(agent, obs[r], skills[r], norm, False) for r in (slice(0, 3), slice(3, 8))])
    torch.manual_seed(4)
    got = np.empty_like(want)
    for r in (slice(0, 3), slice(3, 8)):
        fast(obs[r], r, got[r])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)


def test_actor_reads_the_current_weights() -> None:
    agent, obs, skills, norm = setup("half_cheetah")
    before = np.empty((8, agent.policy.trunk[-1].out_features // 2), np.float32)
    actor(agent, skills, norm, True)(obs, slice(None), before)
    with torch.no_grad():
        agent.policy.trunk[-1].bias.add_(1.0)  # as an optimiser step does, in place
    after = np.empty_like(before)
    actor(agent, skills, norm, True)(obs, slice(None), after)
    np.testing.assert_allclose(after, reference(agent, obs, skills, norm, True), rtol=0, atol=1e-5)
    assert not np.allclose(after, before)


def test_state_mlp_policies_act_through_actor() -> None:
    agent, _, skills, norm = setup("point", "smoke")
    assert isinstance(actor(agent, skills, norm, False), Actor)


def test_pixel_policies_act_through_the_torch_path() -> None:
    cfg = make_config("smoke", "quadruped")
    prior = SkillPrior(cfg.skill_dim, cfg.discrete_skills)
    agent = Metra((9, 64, 64), 12, prior, cfg, torch.device("cpu"))
    assert not fits(agent)
    norm = Normaliser(np.float32(0), np.float32(255))
    assert isinstance(actor(agent, prior.sample(2, np.random.default_rng(0)), norm, True), TorchActor)
    with pytest.raises(ValueError, match="Actor needs"):
        Actor(agent, prior.sample(2, np.random.default_rng(0)), norm, True)


def plain_actions(agent: Metra, obs: np.ndarray, skills: np.ndarray, norm: Normaliser, det: bool) -> np.ndarray:
    """`Actor`'s arithmetic written out plainly (F.linear, tanh, the numpy tail): what every
    optimisation of `Actor` must reproduce bit for bit."""
    x = torch.from_numpy(np.concatenate([norm(obs), skills], axis=1).astype(np.float32))
    linears = [m for m in agent.policy.trunk if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for i, m in enumerate(linears):
            x = torch.nn.functional.linear(x, m.weight, m.bias)
            x = x.tanh() if i < len(linears) - 1 else x
    y = x.numpy()
    a = y.shape[1] // 2
    if det:
        return np.tanh(y[:, :a])
    noise = torch.randn(len(y), a).numpy()
    return np.tanh(y[:, :a] + np.exp(np.clip(y[:, a:], agent.policy.log_std_min, LOG_STD_MAX)) * noise)


@pytest.mark.parametrize("deterministic", [False, True])
def test_actor_is_bit_identical_to_its_plain_arithmetic(deterministic: bool) -> None:
    agent, obs, skills, norm = setup("ant")
    fast = Actor(agent, skills, norm, deterministic)
    torch.manual_seed(2)
    want = [plain_actions(agent, obs[r] + k, skills[r], norm, deterministic) for k in range(3) for r in GROUPS]
    torch.manual_seed(2)
    got = []
    for k in range(3):
        for r in GROUPS:
            out = np.empty_like(want[0] if r == GROUPS[0] else want[1])
            fast(obs[r] + k, r, out)
            got.append(out)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)


@pytest.mark.parametrize(
    ("env_name", "physics_threads", "batch_threads"), [("half_cheetah", 1, 1), ("half_cheetah", 1, 2), ("ant", 2, 1)]
)
def test_rollout_is_bit_identical_to_acting_and_stepping_written_out(
    env_name: str, physics_threads: int, batch_threads: int
) -> None:
    """The rollout loop (batched or pipelined) adds nothing to the plain loop: act per group of
    rows, step, store; every field bit for bit."""
    torch.manual_seed(0)
    agent, _, skills, norm = setup(env_name)
    steps, seeds = 25, list(range(10, 18))
    env = VectorEnv(env_name, 8, episode_steps=steps, physics_threads=physics_threads, batch_threads=batch_threads)
    torch.manual_seed(7)
    traj = rollout(env, agent, skills, seeds, norm, deterministic=False)

    plain = VectorEnv(env_name, 8, episode_steps=steps, physics_threads=1)
    torch.manual_seed(7)
    b = plain.reset(seeds)
    fields = {k: [getattr(b, k).copy()] for k in ("obs", "xy", "pitch", "qpos", "qvel")}
    actions = []
    for _ in range(steps):
        a = np.concatenate([plain_actions(agent, b.obs[r], skills[r], norm, False) for r in env.groups])
        actions.append(a)
        b = plain.step(a)
        for k, v in fields.items():
            v.append(getattr(b, k).copy())
    np.testing.assert_array_equal(traj.action, np.stack(actions, 1))
    for k, v in fields.items():
        np.testing.assert_array_equal(getattr(traj, k), np.stack(v, 1).astype(getattr(traj, k).dtype))
    assert np.ptp(traj.action) > 0.5  # real actions, not a constant
    env.close()
    plain.close()


def test_acting_torch_rolls_out_through_the_policy_forward() -> None:
    """`--acting torch`: every step's actions are `Metra.act`'s on the normalised observations,
    bit for bit, as rollouts acted before `Actor` (runs before 2026-12-01 reproduce per seed)."""
    torch.manual_seed(0)
    agent, _, skills, norm = setup("point")
    steps, seeds = 15, list(range(20, 28))
    env = VectorEnv("point", 8, episode_steps=steps)
    torch.manual_seed(5)
    traj = rollout(env, agent, skills, seeds, norm, False, acting_path("torch"))
    plain = VectorEnv("point", 8, episode_steps=steps)
    torch.manual_seed(5)
    b, actions = plain.reset(seeds), []
    for _ in range(steps):
        a = np.concatenate([reference(agent, b.obs[r], skills[r], norm, False) for r in env.groups])
        actions.append(a)
        b = plain.step(a)
    np.testing.assert_array_equal(traj.action, np.stack(actions, 1))
    assert np.ptp(traj.action) > 0.5
    env.close()
    plain.close()


def test_acting_paths_by_name() -> None:
    assert acting_path("fast") is actor and acting_path("torch") is TorchActor
    assert tuple(PATHS) == ACTING_PATHS  # what the config accepts is what the rollouts can do
    with pytest.raises(ValueError, match="unknown acting path 'numpy'; valid: fast, torch"):
        acting_path("numpy")
    with pytest.raises(ValueError, match="unknown acting path 'numpy'"):
        make_config("smoke", "point", acting="numpy")
