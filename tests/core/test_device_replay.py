"""The device-resident data path (trainer/device_replay.py) gives exactly the batches of the host
sampler for the same RNG — with views of the host arrays (the CPU default) and with device copies
(the GPU's code path, run here on the CPU)."""

import numpy as np
import pytest
import torch

from trainer.device_replay import DeviceReplay
from trainer.replay import TrajectoryReplay
from trainer.rollout import Normaliser
from trainer.skills import SkillPrior

STEPS, GRAD_STEPS, BATCH = 12, 5, 16


def filled(obs_shape: tuple[int, ...], dtype: type) -> TrajectoryReplay:
    r = TrajectoryReplay(6 * STEPS, STEPS, obs_shape, 3, 4, 5, 5, dtype)
    rng = np.random.default_rng(1)
    for epoch in range(3):  # 9 trajectories in a ring of 6: slots reused
        n = 3
        obs = rng.uniform(0, 255, size=(n, STEPS + 1, *obs_shape)).astype(dtype)
        skill = np.eye(4, dtype=np.float32)[rng.integers(0, 4, size=n)]
        r.add(
            obs,
            rng.normal(size=(n, STEPS, 3)),
            skill,
            rng.normal(size=(n, STEPS + 1, 2)) * 5,
            rng.normal(size=(n, STEPS + 1)),
            rng.normal(size=(n, STEPS + 1, 5)),
            rng.normal(size=(n, STEPS + 1, 5)),
            epoch,
        )
    return r


def rule(xy: np.ndarray, _pitch: np.ndarray) -> np.ndarray:
    return (xy[..., 1] > 0).astype(np.int8) + (xy[..., 1] > 3)


@pytest.mark.parametrize(("obs_shape", "dtype"), [((7,), np.float32), ((3, 4, 4), np.uint8)])
@pytest.mark.parametrize("share", [True, False])
def test_device_batches_equal_the_host_sampler(obs_shape, dtype, share):
    r = filled(obs_shape, dtype)
    prior = SkillPrior(4, discrete=True)
    mean, std = (np.float32(0.0), np.float32(255.0)) if dtype == np.uint8 else (np.arange(7.0), np.arange(7.0) + 1)
    norm = Normaliser(mean, std)
    cpu = torch.device("cpu")
    device = DeviceReplay(r, norm, prior.reward_direction, cpu, rule=rule, share_host_memory=share)
    assert device.shared is share

    host_rng, dev_rng = np.random.default_rng(7), np.random.default_rng(7)
    batches = list(device.batches(*r.sample_indices(GRAD_STEPS, BATCH, dev_rng)))
    assert len(batches) == GRAD_STEPS
    for sampled in batches:
        h = r.sample(BATCH, host_rng)  # the host path, as the trainer did it before

        def t(x: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(x, dtype=torch.float32)

        b = sampled.batch
        assert torch.equal(b.obs, t(norm(h.obs))) and torch.equal(b.next_obs, t(norm(h.next_obs)))
        assert torch.equal(b.action, t(h.action)) and torch.equal(b.skill, t(h.skill))
        assert torch.equal(b.direction, t(prior.reward_direction(h.skill)))
        assert torch.equal(sampled.rule, t(rule(h.xy, h.pitch)))
        assert torch.equal(sampled.next_rule, t(rule(h.next_xy, h.next_pitch)))
        assert b.obs.dtype == torch.float32 and b.obs.shape == (BATCH, *obs_shape)
    assert host_rng.integers(1 << 30) == dev_rng.integers(1 << 30)  # the RNG is left in the same state


def test_device_copies_follow_new_trajectories():
    r = filled((7,), np.float32)
    norm = Normaliser(np.zeros(7), np.ones(7))
    device = DeviceReplay(r, norm, lambda z: z, torch.device("cpu"), share_host_memory=False)
    r.obs[2] += 1.0  # host written, not synced yet
    assert not torch.equal(device.tensors["obs"][2], torch.from_numpy(r.obs[2]))
    device.sync(np.array([2]))
    assert torch.equal(device.tensors["obs"][2], torch.from_numpy(r.obs[2]))


def test_a_whole_replay_is_copied_to_the_device_in_parts(monkeypatch: pytest.MonkeyPatch) -> None:
    """A resume copies every slot: in parts of SYNC_SLOTS, so no second whole replay is made on the
    host and on the device at once; every part lands where it belongs."""
    import trainer.device_replay as device_replay

    monkeypatch.setattr(device_replay, "SYNC_SLOTS", 4)
    r = filled((7,), np.float32)
    copied: list[int] = []
    real = torch.Tensor.index_copy_
    monkeypatch.setattr(torch.Tensor, "index_copy_", lambda t, d, i, s: copied.append(len(i)) or real(t, d, i, s))
    device = DeviceReplay(
        r, Normaliser(np.zeros(7), np.ones(7)), lambda z: z, torch.device("cpu"), share_host_memory=False
    )
    assert r.count == 6 and sorted(set(copied)) == [3]  # 6 slots: two parts of 3, each key
    for key, host in (("obs", r.obs), ("action", r.action), ("skill", r.skill)):
        assert torch.equal(device.tensors[key], torch.from_numpy(host))
