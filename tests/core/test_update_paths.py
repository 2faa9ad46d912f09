"""The gradient step's faster paths compute what the plain path computes.

`old_update` is the step as trainer/metra.py wrote it before (one backward pass and one optimiser
step per loss, Adam's per-tensor loop, a Polyak loop, per-class torch.cdist): the default path must
equal it bit for bit; the fused Adam kernel and the compiled networks to float tolerance.
"""

import copy

import pytest
import torch

from trainer.config import make_config
from trainer.fast_ops import fast_ops_pay
from trainer.guidance import CDIST_MM_ROWS, EMPTY_CLASS_DISTANCE, LabelledSets, class_distances, guidance_weight
from trainer.loop import Trainer
from trainer.metra import Metra, TorchBatch
from trainer.networks import EnsembleLinear, SkillLatent, Tanh, TwinQ
from trainer.optim import adam, step_together
from trainer.skills import SkillPrior

OBS, ACT, BATCH = 6, 3, 64


EXACT = dict(fused_adam=False, fast_ops=False)  # the step's arithmetic as old_update does it


def make_agent(**overrides: object) -> Metra:
    torch.manual_seed(0)
    cfg = make_config("smoke", "point", hidden=64, lr=1e-3, **overrides)
    return Metra(OBS, ACT, SkillPrior(2, False), cfg, torch.device("cpu"))


def make_batches(n: int) -> list[TorchBatch]:
    g = torch.Generator().manual_seed(1)
    out = []
    for _ in range(n):
        obs = torch.randn(BATCH, OBS, generator=g)
        z = torch.nn.functional.normalize(torch.randn(BATCH, 2, generator=g), dim=1)
        act = torch.rand(BATCH, ACT, generator=g) * 2 - 1
        out.append(TorchBatch(obs, obs + 0.1 * torch.randn(BATCH, OBS, generator=g), act, z, z))
    return out


def labelled_states(sizes: tuple[int, int, int]) -> list[torch.Tensor]:
    g = torch.Generator().manual_seed(2)
    return [torch.randn(n, OBS, generator=g) for n in sizes]


def old_update(agent: Metra, b: TorchBatch, sets: list[torch.Tensor]) -> dict[str, torch.Tensor]:
    c = agent.cfg
    lam = agent.log_lambda.exp().detach()
    phi_s, phi_next = agent.phi(torch.cat([b.obs, b.next_obs])).chunk(2)
    delta = phi_next - phi_s
    with torch.no_grad():  # as LabelledSets.embeddings: the non-empty classes in one pass
        emb = agent.phi(torch.cat([s for s in sets if len(s)])).split([len(s) for s in sets if len(s)])
    it = iter(emb)
    cols = [
        torch.cdist(phi_next.detach(), next(it)).min(dim=1).values if len(s) else torch.full((BATCH,), 1e10)
        for s in sets
    ]
    w = torch.softmax(-torch.stack(cols, 1), 1) @ torch.tensor([0.0, 1.0, 2.0])
    projection = (delta * b.direction).sum(-1)
    penalty = torch.clamp(1.0 - delta.pow(2).sum(-1), max=c.epsilon)
    guided = w * projection
    phi_loss = -(guided + lam * penalty).mean()
    agent.phi_opt.zero_grad(set_to_none=True)
    phi_loss.backward()
    agent.phi_opt.step()
    lambda_loss = agent.log_lambda * penalty.detach().mean()
    agent.lambda_opt.zero_grad(set_to_none=True)
    lambda_loss.backward()
    agent.lambda_opt.step()
    reward = guided.detach()

    alpha = agent.log_alpha.exp().detach()
    with torch.no_grad():
        next_action, next_logp = agent.policy.sample(b.next_obs, b.skill)
        q_next = agent.qf_target(b.next_obs, b.skill, next_action).min(0).values
        target = reward + c.gamma * (q_next - alpha * next_logp)
    q = agent.qf(b.obs, b.skill, b.action)
    qf_loss = 0.5 * (q - target).pow(2).mean(1).sum()
    agent.qf_opt.zero_grad(set_to_none=True)
    qf_loss.backward()
    agent.qf_opt.step()
    action, logp = agent.policy.sample(b.obs, b.skill)
    agent.qf.requires_grad_(False)
    q_pi = agent.qf(b.obs, b.skill, action).min(0).values
    agent.qf.requires_grad_(True)
    policy_loss = (alpha * logp - q_pi).mean()
    agent.policy_opt.zero_grad(set_to_none=True)
    policy_loss.backward()
    agent.policy_opt.step()
    alpha_loss = -(agent.log_alpha * (logp.detach() + agent.target_entropy)).mean()
    agent.alpha_opt.zero_grad(set_to_none=True)
    alpha_loss.backward()
    agent.alpha_opt.step()
    with torch.no_grad():
        for t, p in zip(agent.qf_target.parameters(), agent.qf.parameters(), strict=True):
            t.lerp_(p, c.tau)
    return dict(phi_loss=phi_loss, lambda_loss=lambda_loss, qf_loss=qf_loss, policy_loss=policy_loss)


def new_update(agent: Metra, b: TorchBatch, sets: list[torch.Tensor]) -> dict[str, torch.Tensor]:
    labelled = LabelledSets(lambda x: x, torch.device("cpu"))
    for i, s in enumerate(sets):
        if len(s):
            labelled.set(f"q{i}", s.numpy(), i)

    def w(_s: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
        return guidance_weight(n, labelled.embeddings(agent.phi, agent.phi_version))

    return agent.update(b, w)


def run(agent: Metra, step, sets: list[torch.Tensor], n: int = 3) -> list[dict[str, torch.Tensor]]:
    torch.manual_seed(123)  # the policy's sampling noise
    return [{k: v.detach().clone() for k, v in step(agent, b, sets).items()} for b in make_batches(n)]


def tensors(agent: Metra) -> dict[str, torch.Tensor]:
    nets = ("phi", "qf", "qf_target", "policy")
    out = {f"{net}.{k}": v for net in nets for k, v in getattr(agent, net).state_dict().items()}
    return out | {"log_alpha": agent.log_alpha.detach(), "log_lambda": agent.log_lambda.detach()}


def per_tensor_loop(agent: Metra) -> Metra:
    """A copy whose optimisers step with Adam's per-tensor loop (torch's CPU default before)."""
    old = copy.deepcopy(agent)
    for opt in (old.phi_opt, old.qf_opt, old.policy_opt, old.alpha_opt, old.lambda_opt):
        for group in opt.param_groups:
            group.update(foreach=False, fused=None)
    return old


@pytest.mark.parametrize("sizes", [(40, 19, 30), (40, 0, 19)])
def test_exact_step_equals_the_old_path_bit_for_bit(sizes):
    sets = labelled_states(sizes)
    agent = make_agent(**EXACT)
    old = per_tensor_loop(agent)
    got, want = run(agent, new_update, sets), run(old, old_update, sets)
    for g, o in zip(got, want, strict=True):
        for k in o:
            assert torch.equal(g[k], o[k]), k
    ours, theirs = tensors(agent), tensors(old)
    for k in theirs:
        assert torch.equal(ours[k], theirs[k]), k


@pytest.mark.parametrize("options", [{}, {"fused_adam": False}, {"fast_ops": False}, {"fast_ops": True}])
def test_default_step_matches_the_old_path_to_float_tolerance(options):
    """The default (fused Adam; fast ops where they pay) and each lever alone, fast ops forced on
    too (on every host: the default may turn them off, trainer/fast_ops.py). One step
    from the same batch lands within float rounding; over several steps Adam's normalisation can
    turn a rounding difference in a near-zero gradient into a visible one, so there only the
    losses are compared."""
    sets = labelled_states((40, 19, 30))
    agent = make_agent(**options)
    assert all(bool(g["fused"]) == options.get("fused_adam", True) for g in agent.qf_opt.param_groups)
    old = per_tensor_loop(make_agent(**EXACT))
    run(agent, new_update, sets, n=1), run(old, old_update, sets, n=1)
    ours, theirs = tensors(agent), tensors(old)
    for k in theirs:
        torch.testing.assert_close(ours[k], theirs[k], rtol=1e-5, atol=1e-7)
    agent, old = make_agent(**options), per_tensor_loop(make_agent(**EXACT))
    got, want = run(agent, new_update, sets, n=4), run(old, old_update, sets, n=4)
    for g, o in zip(got, want, strict=True):
        for k in o:
            torch.testing.assert_close(g[k], o[k], rtol=1e-3, atol=1e-5)


def test_the_trainer_fixes_the_fast_ops_default_for_its_machine(tmp_path):
    """`fast_ops` None (the default) becomes this machine's choice when the trainer starts, so
    config.json and a resume carry a bool; the networks are built with it; a given value stays."""
    for given in (None, True, False):
        cfg = make_config("smoke", "point", out=str(tmp_path / str(given)), fast_ops=given)
        trainer = Trainer(cfg, progress=False)
        want = fast_ops_pay(torch.device("cpu")) if given is None else given
        assert trainer.cfg.fast_ops is want
        trunk_tanh = [m for m in trainer.agent.policy.trunk if isinstance(m, torch.nn.Tanh)]
        assert all(isinstance(m, Tanh) is want for m in trunk_tanh) and trunk_tanh
        trainer.env.close()


def test_a_loaded_optimiser_steps_with_the_runs_kernel():
    fused, plain = make_agent(), make_agent(fused_adam=False)
    plain.load_state_dict(fused.state_dict())
    assert all(g["foreach"] and not g["fused"] for g in plain.phi_opt.param_groups)
    fused.load_state_dict(plain.state_dict())
    assert all(g["fused"] for g in fused.phi_opt.param_groups)


@pytest.mark.parametrize("sizes", [(300, 20, 1), (7, 0, 0), (0, 5, 40)])
@pytest.mark.parametrize("rows", [CDIST_MM_ROWS, CDIST_MM_ROWS + 1, 256])
def test_class_distances_equal_per_class_cdist(sizes, rows):
    g = torch.Generator().manual_seed(3)
    z = torch.randn(rows, 2, generator=g)
    sets = [torch.randn(n, 2, generator=g) for n in sizes]
    want = torch.stack(
        [torch.cdist(z, s).min(dim=1).values if len(s) else torch.full((rows,), EMPTY_CLASS_DISTANCE) for s in sets],
        dim=1,
    )
    assert torch.equal(class_distances(z, sets), want)


@pytest.mark.compile
def test_compiled_networks_match_eager_to_float_tolerance():
    sets = labelled_states((40, 19, 30))
    compiled, eager = make_agent(compile=True), make_agent()
    compiled.compile()
    got, want = run(compiled, new_update, sets), run(eager, new_update, sets)
    for g, o in zip(got, want, strict=True):
        for k in o:
            torch.testing.assert_close(g[k], o[k], rtol=1e-3, atol=1e-5)
    assert compiled.phi.state_dict().keys() == eager.phi.state_dict().keys()  # checkpoints unchanged


def test_cli_compile_is_a_bare_flag():
    import argparse

    from trainer.cli import add_arguments

    p = argparse.ArgumentParser()
    add_arguments(p)
    assert p.parse_args(["--compile"]).compile is True
    assert p.parse_args(["--compile", "false"]).compile is False
    assert p.parse_args([]).compile is None


def adam_pair(fused: bool, lr_b: float = 1e-3) -> tuple[list[torch.optim.Adam], list[torch.optim.Adam]]:
    """Two identical sets of (network optimiser, scalar optimiser), e.g. π's and α's."""
    torch.manual_seed(4)
    net, scalar = torch.nn.Linear(5, 3), torch.zeros((), requires_grad=True)
    twins = []
    for _ in range(2):
        n, s = copy.deepcopy(net), scalar.detach().clone().requires_grad_(True)
        twins.append([adam(n.parameters(), 1e-3, fused), adam([s], lr_b, fused)])
    return twins[0], twins[1]


def set_grads(opts: list[torch.optim.Adam], step: int) -> None:
    g = torch.Generator().manual_seed(10 + step)
    for opt in opts:
        for group in opt.param_groups:
            for p in group["params"]:
                p.grad = torch.randn(p.shape, generator=g) * 10.0 ** -(step % 4)


def params(opts: list[torch.optim.Adam]) -> list[torch.Tensor]:
    return [p for opt in opts for group in opt.param_groups for p in group["params"]]


@pytest.mark.parametrize("fused", [False, True])
@pytest.mark.parametrize("lr_b", [1e-3, 3e-4])  # equal hyper-parameters: one call; different: one by one
def test_step_together_equals_separate_steps_bit_for_bit(fused, lr_b):
    together, separate = adam_pair(fused, lr_b)
    for step in range(5):
        set_grads(together, step), set_grads(separate, step)
        step_together(*together)
        for opt in separate:
            opt.step()
    for a, b in zip(params(together), params(separate), strict=True):
        assert torch.equal(a, b)
    for t, s in zip(together, separate, strict=True):  # the saved state too: checkpoints unchanged
        for pa, pb in zip(params([t]), params([s]), strict=True):
            for key in ("step", "exp_avg", "exp_avg_sq"):
                assert torch.equal(t.state[pa][key], s.state[pb][key]), key
    moved = params(together)[0]
    assert not torch.equal(moved, params(adam_pair(fused)[0])[0])  # the steps did move the weights


def test_phi_steps_before_sac_reads_it_when_a_pixel_encoder_is_shared():
    cfg = make_config("smoke", "point", hidden=32, encoder="shared")
    agent = Metra((3, 64, 64), ACT, SkillPrior(2, False), cfg, torch.device("cpu"))
    assert not agent.phi_apart  # φ's step changes the encoder Q and π read: it cannot wait
    assert make_agent().phi_apart


def test_fast_tanh_equals_torch_tanh_with_its_gradient():
    x = torch.cat([torch.linspace(-12, 12, 4001), torch.tensor([0.0, 1e-9, -1e-7, 40.0, -40.0])])
    x.requires_grad_(True)
    (y := Tanh()(x)).backward(torch.ones_like(x))
    ref = x.detach().clone().requires_grad_(True)
    torch.tanh(ref).backward(torch.ones_like(ref))
    torch.testing.assert_close(y, torch.tanh(ref), rtol=0, atol=2e-7)
    torch.testing.assert_close(x.grad, ref.grad, rtol=0, atol=4e-7)
    assert y.abs().max() <= 1.0


@pytest.mark.parametrize("shape", [(2, 64, 32), (64, 32)])  # a member's own rows, or rows shared by both
def test_one_output_ensemble_layer_fast_path_equals_bmm(shape):
    torch.manual_seed(0)
    fast, exact = EnsembleLinear(2, 32, 1), EnsembleLinear(2, 32, 1, fast=False)
    exact.load_state_dict(fast.state_dict())
    x = torch.randn(*shape, requires_grad=True)
    x2 = x.detach().clone().requires_grad_(True)
    g = torch.randn(2, 64, 1)
    (out := fast(x)).backward(g)
    exact(x2).backward(g)
    assert out.shape == (2, 64, 1)
    torch.testing.assert_close(out, exact(x2), rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(x.grad, x2.grad, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(fast.weight.grad, exact.weight.grad, rtol=1e-5, atol=1e-6)


def test_in_place_relu_gives_out_of_place_values_and_gradients_bit_for_bit():
    torch.manual_seed(0)
    phi, qf = SkillLatent(OBS, 2, 32, 2), TwinQ(OBS + 2 + ACT, 32, 2, fast=False)
    obs, z, act = torch.randn(BATCH, OBS), torch.randn(BATCH, 2), torch.randn(BATCH, ACT)
    assert all(m.inplace for m in phi.modules() if isinstance(m, torch.nn.ReLU))

    def phi_out_of_place() -> torch.Tensor:
        *hidden, last = [m for m in phi.net if isinstance(m, torch.nn.Linear)]
        x = obs
        for layer in hidden:
            x = torch.relu(layer(x))
        return last(x)

    def qf_out_of_place() -> torch.Tensor:
        x = torch.cat([obs, z, act], -1).expand(2, -1, -1)
        *hidden, last = qf.layers
        for layer in hidden:
            x = torch.relu(torch.baddbmm(layer.bias, x, layer.weight))
        return torch.baddbmm(last.bias, x, last.weight).squeeze(-1)

    def values_and_grads(net: torch.nn.Module, forward) -> tuple[torch.Tensor, list[torch.Tensor]]:
        net.zero_grad(set_to_none=True)
        (out := forward()).pow(2).sum().backward()
        return out.detach(), [p.grad.clone() for p in net.parameters()]

    for net, ours, reference in (
        (phi, lambda: phi(obs), phi_out_of_place),
        (qf, lambda: qf(obs, z, act), qf_out_of_place),
    ):
        (out_a, g_a), (out_b, g_b) = values_and_grads(net, ours), values_and_grads(net, reference)
        assert torch.equal(out_a, out_b)
        assert all(torch.equal(a, b) for a, b in zip(g_a, g_b, strict=True))
