"""The replay as the gradient steps see it: tensors on the training device, batches gathered there.

On a GPU the states the updates read — raw observations (pixel frames stay uint8), actions, the
per-trajectory reward direction and, for the Oracle baseline, the rule's g(s) per state — are
copied to the device once, when an epoch's trajectories are stored. An epoch's batch indices are
drawn on the host with the run's RNG (the same draws as `TrajectoryReplay.sample`) and uploaded in
one copy; each gradient step then gathers, converts uint8→float and normalises on the device,
with no host↔device copy and no host sync. On the CPU the tensors share the replay's numpy
memory, so nothing is copied at all. Either way the batches equal the host sampler's.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import torch

from trainer.metra import TorchBatch
from trainer.replay import TrajectoryReplay
from trainer.rollout import Normaliser

SYNC_SLOTS = 64  # trajectories copied to the device at a time (a pixel Quadruped one holds 201 × 9 × 64 × 64 bytes)
# g(s) ∈ {0, 1, 2} of the task rule for states given as (…, 2) x-y and (…) pitch arrays
StateRule = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class DeviceBatch:
    batch: TorchBatch  # normalised s, s′, a, z, direction
    rule: torch.Tensor | None  # g(s), when the replay keeps the rule
    next_rule: torch.Tensor | None  # g(s′)


class DeviceReplay:
    def __init__(
        self,
        replay: TrajectoryReplay,
        normalise: Normaliser,
        reward_direction: Callable[[np.ndarray], np.ndarray],
        device: torch.device,
        rule: StateRule | None = None,
        share_host_memory: bool | None = None,
    ) -> None:
        """`share_host_memory`: views of the numpy arrays (default on the CPU) or device copies
        (default elsewhere; also on the CPU, so that tests run the GPU's code path)."""
        self.replay, self.device, self._direction_of, self._rule = replay, device, reward_direction, rule
        self.mean = torch.tensor(normalise.mean, device=device)  # cached constants (copies)
        self.std = torch.tensor(normalise.std, device=device)
        r = replay
        self._host_direction = np.zeros_like(r.skill)
        self._host_g = np.zeros(r.pitch.shape, np.float32)
        host = {
            "obs": r.obs,
            "action": r.action,
            "skill": r.skill,
            "direction": self._host_direction,
            "g": self._host_g,
        }
        self.shared = device.type == "cpu" if share_host_memory is None else share_host_memory
        if self.shared:  # views of the numpy arrays: zero copies
            self.tensors = {k: torch.from_numpy(v) for k, v in host.items()}
        else:
            self.tensors = {k: torch.zeros_like(torch.from_numpy(v), device=device) for k, v in host.items()}
        self._host = host
        self.sync(np.arange(r.count))

    def sync(self, slots: np.ndarray) -> None:
        """Bring trajectory slots that were just written (or restored) to the device."""
        if len(slots) == 0:
            return
        r = self.replay
        self._host_direction[slots] = self._direction_of(r.skill[slots])
        if self._rule is not None:
            self._host_g[slots] = self._rule(r.xy[slots], r.pitch[slots])
        if not self.shared:  # in parts: a resume syncs every slot, and a whole copy of a pixel replay is GBs
            for part in np.array_split(slots, -(-len(slots) // SYNC_SLOTS)):
                index = torch.as_tensor(part, device=self.device)
                for key, tensor in self.tensors.items():
                    tensor.index_copy_(0, index, torch.from_numpy(self._host[key][part]).to(self.device))

    def normalised(self, raw: torch.Tensor) -> torch.Tensor:
        return (raw.to(torch.float32) - self.mean) / self.std

    def batches(self, i: np.ndarray, t: np.ndarray) -> Iterator[DeviceBatch]:
        """The batches of index arrays (steps, B) from `TrajectoryReplay.sample_indices`."""
        index = torch.as_tensor(np.stack([i, t]), device=self.device)  # the epoch's one upload
        obs, g = self.tensors["obs"], self.tensors["g"]
        rule = self._rule is not None
        for ik, tk in zip(index[0], index[1], strict=True):
            yield DeviceBatch(
                TorchBatch(
                    self.normalised(obs[ik, tk]),
                    self.normalised(obs[ik, tk + 1]),
                    self.tensors["action"][ik, tk],
                    self.tensors["skill"][ik],
                    self.tensors["direction"][ik],
                ),
                g[ik, tk] if rule else None,
                g[ik, tk + 1] if rule else None,
            )
