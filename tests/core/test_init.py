"""Weight initialisation and the policy's log-std floor: the reference's garage schemes by default,
PyTorch's with `--init torch`."""

import math

import torch

from trainer.config import make_config
from trainer.metra import Metra
from trainer.networks import LOG_STD_MIN
from trainer.skills import SkillPrior


def agent(**kw) -> Metra:
    torch.manual_seed(0)
    cfg = make_config("smoke", "point", hidden=256, **kw)
    return Metra(29, 8, SkillPrior(2, False), cfg, torch.device("cpu"))


def linears(module: torch.nn.Module) -> list[torch.nn.Linear]:
    return [m for m in module.modules() if isinstance(m, torch.nn.Linear)]


@torch.no_grad()
def test_reference_init_is_xavier_with_zero_biases() -> None:
    a = agent()
    for layer in linears(a.phi) + linears(a.policy.trunk)[:-1]:  # Xavier-uniform
        fan_out, fan_in = layer.weight.shape
        bound = math.sqrt(6.0 / (fan_in + fan_out))
        assert float(layer.weight.abs().max()) <= bound + 1e-6
        assert float(layer.weight.abs().max()) > 0.9 * bound  # spread over the whole interval
        assert torch.count_nonzero(layer.bias) == 0
    last = linears(a.policy.trunk)[-1]  # Xavier-normal output layer
    expected = math.sqrt(2.0 / sum(last.weight.shape))
    assert abs(float(last.weight.std()) - expected) < 0.1 * expected
    for layer in a.qf.layers:  # Xavier-normal, per twin
        inp, out = layer.weight.shape[1:]
        assert abs(float(layer.weight[0].std()) - math.sqrt(2.0 / (inp + out))) < 0.1 * math.sqrt(2.0 / (inp + out))
        assert torch.count_nonzero(layer.bias) == 0
    for p, q in zip(a.qf.parameters(), a.qf_target.parameters(), strict=True):
        assert torch.equal(p, q)  # the target starts as a copy of the re-initialised critic


def test_torch_init_and_log_std_floor() -> None:
    a = agent(init="torch", log_std_min=-5.0)
    assert all(torch.count_nonzero(layer.bias) > 0 for layer in linears(a.phi))  # PyTorch's uniform biases
    assert a.policy.log_std_min == -5.0
    assert agent().policy.log_std_min == LOG_STD_MIN == math.log(1e-6)
    with torch.no_grad():
        a.policy.trunk[-1].bias.fill_(-100.0)
        _, log_std = a.policy(torch.zeros(1, 29), torch.zeros(1, 2))
    assert torch.all(log_std == -5.0)
