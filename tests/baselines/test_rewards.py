"""Each baseline's reward (and the ablations' variants) on hand-built transitions."""

import math

import numpy as np
import pytest
import torch

from trainer.config import make_config
from trainer.ddg import attach_projection
from trainer.diayn import Diayn, diayn_reward, skill_log_likelihood
from trainer.dodont import dodont_weight
from trainer.downstream.goal import goal_reward
from trainer.downstream.ppo import gae
from trainer.downstream.zero_shot import motion_returns
from trainer.instruction import InstructionClassifier
from trainer.lsd import Lsd
from trainer.metra import Metra, TorchBatch, guided_reward
from trainer.skills import SkillPrior


def batch(n: int = 64, obs_dim: int = 4, skill_dim: int = 2, seed: int = 0) -> TorchBatch:
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(n, obs_dim, generator=g)
    z = torch.nn.functional.normalize(torch.randn(n, skill_dim, generator=g), dim=1)
    return TorchBatch(
        obs, obs + 0.3 * torch.randn(n, obs_dim, generator=g), torch.rand(n, 2, generator=g) * 2 - 1, z, z
    )


def cfg(**kw):
    return make_config("smoke", "point", hidden=32, lr=1e-2, **kw)


def test_diayn_discrete_reward_is_log_q_minus_log_prior():
    logits = torch.log(torch.tensor([[0.5, 0.25, 0.25], [0.2, 0.2, 0.6]]))
    z = torch.tensor([[1.0, 0, 0], [0, 0, 1.0]])
    log_q = skill_log_likelihood(logits, z, discrete=True)
    assert torch.allclose(log_q, torch.log(torch.tensor([0.5, 0.6])))
    r = diayn_reward(log_q, 3, discrete=True)  # log q(z|s′) − log(1/3)
    assert torch.allclose(r, torch.log(torch.tensor([1.5, 1.8])))


def test_diayn_continuous_reward_is_gaussian_log_likelihood():
    z = torch.tensor([[1.0, 0.0]])
    assert math.isclose(float(skill_log_likelihood(z, z, discrete=False)), -math.log(2 * math.pi), rel_tol=1e-6)
    mean = torch.tensor([[0.0, 0.0]])
    assert math.isclose(
        float(diayn_reward(skill_log_likelihood(mean, z, False), 2, False, "sphere")),
        -0.5 - math.log(2 * math.pi),
        rel_tol=1e-6,
    )
    # A learned diagonal std: N(z; 0, diag(e^{2·log σ})) at z = (1, 0) with σ = (2, 0.5).
    log_std = torch.log(torch.tensor([[2.0, 0.5]]))
    expected = -0.5 * (1 / 4) - math.log(2.0) - math.log(0.5) - math.log(2 * math.pi)
    assert math.isclose(float(skill_log_likelihood(mean, z, False, log_std)), expected, rel_tol=1e-6)
    # The reference adds log D (its "baseline") to the continuous reward too.
    r = diayn_reward(skill_log_likelihood(mean, z, False, log_std), 2, False, "reference")
    assert math.isclose(float(r), expected + math.log(2), rel_tol=1e-6)


def test_diayn_reference_variant_gaussian_prior_fixed_alpha_learned_std():
    torch.manual_seed(0)
    c = cfg(method="diayn")
    assert c.diayn == "reference"
    prior = SkillPrior.for_config(c)
    assert prior.gaussian and not prior.discrete
    z = prior.sample(4000, np.random.default_rng(0))
    assert abs(float(np.linalg.norm(z, axis=1).std())) > 0.3  # not on the sphere
    assert np.allclose(z.mean(0), 0, atol=0.05) and np.allclose(z.std(0), 1, atol=0.05)
    agent = Diayn(4, 2, prior, c, torch.device("cpu"))
    assert math.isclose(float(agent.log_alpha.detach().exp()), 0.1, rel_tol=1e-6)
    zt = torch.as_tensor(z[:64])
    b = batch()
    b = TorchBatch(b.obs, torch.cat([zt, zt], dim=1) + 0.01 * b.next_obs, b.action, zt, zt)  # s′ reveals z
    with torch.no_grad():
        start = float(agent.phi.log_std(b.next_obs).mean())
    for _ in range(200):
        agent.update(b, None)
    assert math.isclose(float(agent.log_alpha.detach().exp()), 0.1, rel_tol=1e-6)  # α never learned
    with torch.no_grad():
        assert float(agent.phi.log_std(b.next_obs).mean()) < start - 0.5  # the discriminator grew confident
    sphere = cfg(method="diayn", diayn="sphere")
    assert not SkillPrior.for_config(sphere).gaussian
    assert Diayn(4, 2, SkillPrior.for_config(sphere), sphere, torch.device("cpu")).learn_alpha


def test_diayn_update_uses_the_discriminator_reward_and_learns_it():
    torch.manual_seed(0)
    prior = SkillPrior(4, discrete=True)
    agent = Diayn(4, 2, prior, cfg(skill_dim=4, discrete_skills=True), torch.device("cpu"))
    b = batch(skill_dim=4)
    z = torch.eye(4)[torch.arange(64) % 4]
    b = TorchBatch(b.obs, b.obs.clone() + torch.eye(4)[torch.arange(64) % 4] * 3, b.action, z, z)  # s′ reveals z
    expected = diayn_reward(skill_log_likelihood(agent.phi(b.next_obs), z, True), 4, True).mean()
    info = agent.update(b, None)
    assert torch.isclose(info["reward"], expected.detach(), atol=1e-5)
    for _ in range(100):
        agent.update(b, None)
    with torch.no_grad():
        assert float(skill_log_likelihood(agent.phi(b.next_obs), z, True).exp().mean()) > 0.9


def test_lsd_reward_is_the_latent_projection_and_phi_is_one_lipschitz():
    torch.manual_seed(0)
    agent = Lsd(4, 2, SkillPrior(2, False), cfg(), torch.device("cpu"))
    b = batch()
    for _ in range(30):  # power iterations converge on the spectral norms
        agent.phi(b.obs)
    with torch.no_grad():
        delta = agent.phi(b.next_obs) - agent.phi(b.obs)
        expected = (delta * b.direction).sum(-1).mean()
        ratio = delta.norm(dim=1) / (b.next_obs - b.obs).norm(dim=1)
    assert float(ratio.max()) <= 1.0 + 1e-3  # ‖φ(s′) − φ(s)‖ ≤ ‖s′ − s‖₂
    info = agent.update(b, None)
    assert torch.isclose(info["reward"], expected, atol=1e-4)
    assert agent.log_lambda.item() == pytest.approx(math.log(30.0))  # no dual step


def test_guided_reward_multiplicative_and_additive():
    proj, w = torch.tensor([2.0, -1.0]), torch.tensor([0.5, 2.0])
    assert torch.equal(guided_reward(proj, w), torch.tensor([1.0, -2.0]))
    assert torch.equal(guided_reward(proj, w, "additive"), torch.tensor([2.5, 1.0]))


def test_additive_reward_adds_w_to_metras_reward():
    out = {}
    for form, w in (("multiplicative", 1.0), ("additive", 0.5)):
        torch.manual_seed(0)
        agent = Metra(4, 2, SkillPrior(2, False), cfg(reward_form=form), torch.device("cpu"))
        out[form] = float(agent.update(batch(), lambda s, n, w=w: torch.full((64,), w))["reward"])
    assert out["additive"] == pytest.approx(out["multiplicative"] + 0.5, abs=1e-5)


def fitted_classifier(c) -> InstructionClassifier:
    clf = InstructionClassifier(4, c, torch.device("cpu"))
    good = torch.randn(50, 4) + torch.tensor([3.0, 0, 0, 0])
    bad = torch.randn(50, 4) - torch.tensor([3.0, 0, 0, 0])
    clf.fit([bad, torch.zeros(0, 4), good])
    clf.fitted = (("q", 0),)
    return clf


def test_dodont_weight_is_twice_the_classifier_probability():
    c = cfg(classifier_steps=200)
    cpu = torch.device("cpu")
    assert dodont_weight(InstructionClassifier(4, c, cpu), np.zeros((3, 4)), cpu) is None  # no labels: w ≡ 1
    clf = fitted_classifier(c)
    s = np.array([[3.0, 0, 0, 0], [-3.0, 0, 0, 0]], np.float32)
    w = dodont_weight(clf, s, torch.device("cpu"))(torch.zeros(2, 2), torch.zeros(2, 2))
    assert torch.allclose(w, 2 * clf.prob(torch.as_tensor(s)))
    assert w[0] > 1.9 and w[1] < 0.1  # desirable ≈ 2 (COLLIE's "good"), undesirable ≈ 0


def test_ddg_phi_reads_the_frozen_classifier_encoder():
    torch.manual_seed(0)
    c = cfg(method="ddg", classifier_steps=50)
    agent = Metra(4, 2, SkillPrior(2, False), c, torch.device("cpu"))
    clf = InstructionClassifier(4, c, torch.device("cpu"))
    attach_projection(agent, clf, c)
    b = batch()
    assert torch.allclose(agent.phi(b.obs), agent.phi.head(clf.net.encoder(b.obs)))
    before = [p.clone() for p in clf.net.encoder.parameters()]
    agent.update(b, None)
    assert all(torch.equal(p, q) for p, q in zip(before, clf.net.encoder.parameters(), strict=True))
    out = agent.phi(b.obs).detach()
    clf.fit([b.obs[:32], torch.zeros(0, 4), b.obs[32:]])  # a label change moves the projection
    assert not torch.allclose(out, agent.phi(b.obs))


def test_zero_shot_motion_return_on_a_hand_built_path():
    # 4 steps at 2 units/step along y (dt 0.5 → speed 4), the last state in the bad region
    xy = np.stack([np.zeros(5), np.arange(5) * 2.0], axis=1)[None]
    classes = np.array([[1, 1, 1, 1, 0]])
    assert motion_returns(xy, classes, dt=0.5)[0] == pytest.approx(4 * (1 + 4) - 20)


def test_goal_reward_and_gae():
    r = goal_reward(
        np.array([0.0, 10.0, 12.5, 50.0]), np.array([1.0, 12.0, 10.0, 0.0]), np.array([False, False, False, True])
    )
    assert r.tolist() == [1.0, 1.0, 1.0, -20.0]
    rewards, values = torch.tensor([[1.0], [0.0], [2.0]]), torch.tensor([[0.5], [1.0], [0.0]])
    gamma, lam = 0.9, 0.8
    d = [1 + gamma * 1.0 - 0.5, 0 + gamma * 0.0 - 1.0, 2.0 - 0.0]
    expected = [d[0] + gamma * lam * (d[1] + gamma * lam * d[2]), d[1] + gamma * lam * d[2], d[2]]
    assert torch.allclose(gae(rewards, values, gamma, lam).squeeze(1), torch.tensor(expected))
