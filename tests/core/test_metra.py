"""The METRA/COLLIE gradient step (Eqs. 9–11)."""

import numpy as np
import torch

from trainer.config import make_config
from trainer.metra import Metra, TorchBatch
from trainer.skills import SkillPrior


def make_agent(scale_phi: float) -> tuple[Metra, TorchBatch]:
    torch.manual_seed(0)
    cfg = make_config("smoke", "point", hidden=32, lr=1e-2)
    agent = Metra(4, 2, SkillPrior(2, False), cfg, torch.device("cpu"))
    with torch.no_grad():
        agent.phi.net[-1].weight.mul_(scale_phi)
    obs = torch.randn(64, 4)
    z = torch.nn.functional.normalize(torch.randn(64, 2), dim=1)
    return agent, TorchBatch(obs, obs + torch.randn(64, 4), torch.rand(64, 2) * 2 - 1, z, z)


def test_lambda_rises_while_the_constraint_is_violated():
    agent, batch = make_agent(scale_phi=100.0)  # ‖φ(s′) − φ(s)‖ ≫ 1
    before = agent.log_lambda.item()
    info = agent.update(batch, None)
    assert info["constraint"] > 1.0
    assert agent.log_lambda.item() > before


def test_lambda_falls_while_the_constraint_holds():
    agent, batch = make_agent(scale_phi=1e-4)  # ‖Δφ‖ ≈ 0 → penalty = ε > 0
    before = agent.log_lambda.item()
    agent.update(batch, None)
    assert agent.log_lambda.item() < before


def test_guidance_weight_scales_the_reward():
    agent, batch = make_agent(scale_phi=1.0)
    w = torch.full((64,), 0.5)
    got = agent.update(batch, lambda s, n: w)
    agent2, batch2 = make_agent(scale_phi=1.0)
    ref = agent2.update(batch2, None)
    assert np.isclose(float(got["reward"]), 0.5 * float(ref["reward"]), rtol=1e-5)
    assert float(got["w_mean"]) == 0.5


def test_discrete_skills_use_the_centred_direction():
    prior = SkillPrior(4, discrete=True)
    z = prior.sample(3, np.random.default_rng(0))
    d = prior.reward_direction(z)
    assert np.allclose(d.sum(axis=1), 0.0, atol=1e-6) and np.allclose(d.max(axis=1), 1.0)
