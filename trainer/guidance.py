"""The training-free guidance signal w(s) of COLLIE (Section 4.3) and its smoothing (Section 4.5).

D0, D1, D2 hold the labelled states (bad, neutral, good). Their φ-embeddings are cached and
re-encoded once per φ version, so Eq. 8 costs one small forward pass and a distance matrix.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

EMPTY_CLASS_DISTANCE = 1e10  # an empty label class is "infinitely far" (as the reference)
LABEL_VALUES = (0.0, 1.0, 2.0)  # [0, 1, 2]ᵀ in Eq. 8


CDIST_MM_ROWS = 25  # torch.cdist computes p = 2 distances through one matmul above this many rows


def class_distances(z: torch.Tensor, labelled: list[torch.Tensor]) -> torch.Tensor:
    """d_φ(s, D_i) = min_{s0 ∈ D_i} ‖φ(s0) − φ(s)‖ for i = 0, 1, 2 (Eq. 7). z: (B, k) → (B, 3).

    Squared distances are formed as torch.cdist forms them, ‖z‖² − 2 z·e + ‖e‖² in one augmented
    matmul per class (the same shapes, so the same rounding), and the minimum is taken before the
    clamp at 0 and the square root: both are monotone, so the result equals cdist's bit for bit
    while the square root runs on (B, 3) values instead of (B, N). At most `CDIST_MM_ROWS` rows,
    where cdist may take its direct kernel, still go through cdist."""
    if z.shape[0] <= CDIST_MM_ROWS:
        return _class_distances_cdist(z, labelled)
    z_sq = z.pow(2).sum(-1, keepdim=True)
    left = torch.cat([z.mul(-2), z_sq, torch.ones_like(z_sq)], -1)
    empty = torch.full((z.shape[0],), EMPTY_CLASS_DISTANCE, dtype=z.dtype, device=z.device)
    cols = []
    for emb in labelled:
        if emb.shape[0] == 0:
            cols.append(empty)
        else:
            emb_sq = emb.pow(2).sum(-1, keepdim=True)
            right = torch.cat([emb, torch.ones_like(emb_sq), emb_sq], -1)
            cols.append(left.matmul(right.mT).amin(dim=1).clamp_min_(0).sqrt_())
    return torch.stack(cols, dim=1)


def _class_distances_cdist(z: torch.Tensor, labelled: list[torch.Tensor]) -> torch.Tensor:
    cols = []
    for emb in labelled:
        if emb.shape[0] == 0:
            cols.append(torch.full((z.shape[0],), EMPTY_CLASS_DISTANCE, dtype=z.dtype, device=z.device))
        else:
            cols.append(torch.cdist(z, emb).min(dim=1).values)
    return torch.stack(cols, dim=1)


_LABEL_VECTORS: dict[tuple[torch.dtype, torch.device], torch.Tensor] = {}


def label_vector(dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """[0, 1, 2]ᵀ on `device`, uploaded once (not at every gradient step)."""
    key = (dtype, device)
    if key not in _LABEL_VECTORS:
        _LABEL_VECTORS[key] = torch.tensor(LABEL_VALUES, dtype=dtype, device=device)
    return _LABEL_VECTORS[key]


def guidance_weight(z: torch.Tensor, labelled: list[torch.Tensor]) -> torch.Tensor:
    """w(s) = softmax([−d_φ(s, D_i)]_{i=0..2}) · [0, 1, 2]ᵀ (Eq. 8); 1 when nothing is labelled."""
    if all(emb.shape[0] == 0 for emb in labelled):
        return torch.ones(z.shape[0], dtype=z.dtype, device=z.device)
    probs = torch.softmax(-class_distances(z, labelled), dim=1)
    return probs @ label_vector(z.dtype, z.device)


def smoothing_beta(epoch: int, first_feedback_epoch: int | None, span: float, k_beta: float) -> float:
    """β_e of the smoothing w_e = (1 − β_e)·w + β_e (Section 4.5), as the reference code schedules it.

    Ours (the reference's): β_e = 1 until the first feedback epoch e₀, then
        β_e = max(0, 1 − k_β·(e − e₀)/span),   span = sessions × K,
    so guidance fades in over span/k_β epochs after the first labels (paper schedule: 8 × 1000 / 5
    = 1600 epochs, epochs 2000 → 3600). The reference lowers its rate by k_β/(2·span·G) at each of
    the two reward computations of each of the G gradient steps per epoch (the same slope, but
    within the epoch); we hold β constant over an epoch.
    The paper prints β_e = max(0, 1 − k_β·e/T^e), e counted from the start of training and T^e the
    total epochs. That is *not* the same: with its own numbers (k_β = 5, T^e = 10 000, warm-up
    2000) β reaches 0 at e = 2000, the epoch of the first labels, so guidance would start at full
    strength and the smoothing would only act before any label exists, where w ≡ 1 anyway; on a
    shorter schedule with a proportionally later warm-up it is the same. k_β = ∞ → pure GSD; both
    write k_β = 0 → pure USD, which the config refuses (k_β > 0): pure USD is `--method metra`.
    """
    if first_feedback_epoch is None or epoch < first_feedback_epoch:
        return 1.0
    if np.isinf(k_beta):
        return 0.0
    return float(max(0.0, 1.0 - k_beta * (epoch - first_feedback_epoch) / max(span, 1.0)))


@dataclass
class LabelledSegment:
    obs: np.ndarray  # (H, d) raw observations of σ (uint8 frames for pixel envs, see `kept`)
    label: int  # 0 bad, 1 neutral, 2 good


def kept(obs: np.ndarray) -> np.ndarray:
    """A segment's raw states as they are kept: pixel frames stay uint8 (float32 would take 4× the
    memory and checkpoint, and normalising makes them float anyway), other observations float32.
    The same array as given when it is one of these, so a checkpoint holds it once."""
    arr = np.asarray(obs)
    return arr if arr.dtype == np.uint8 else np.asarray(arr, np.float32)


class LabelledSets:
    """D0/D1/D2, keyed by query id so that a revised label moves a whole segment (undo-safe)."""

    def __init__(self, normalise: Callable[[np.ndarray], np.ndarray], device: torch.device) -> None:
        self.segments: dict[str, LabelledSegment] = {}
        self._normalise, self._device = normalise, device
        self.version = 0  # bumped on every change
        self._tensors: list[torch.Tensor] | None = None
        self._cache_key: tuple[int, int] | None = None
        self._cache: list[torch.Tensor] = []

    def __len__(self) -> int:
        return len(self.segments)

    def set(self, query_id: str, obs: np.ndarray, label: int | None) -> None:
        """Add, relabel (label in {0,1,2}) or withdraw (None) one segment."""
        if label is None:
            self.segments.pop(query_id, None)
        else:
            if label not in (0, 1, 2):
                raise ValueError(f"label must be 0, 1 or 2, got {label!r}")
            self.segments[query_id] = LabelledSegment(kept(obs), int(label))
        self.version += 1
        self._tensors = None

    def counts(self) -> tuple[int, int, int]:
        """Number of labelled *states* in D0, D1, D2."""
        out = [0, 0, 0]
        for seg in self.segments.values():
            out[seg.label] += seg.obs.shape[0]
        return out[0], out[1], out[2]

    def n_states(self) -> int:
        return sum(self.counts())

    def all_obs(self) -> np.ndarray:
        """Every labelled state (raw), any class: the set D used by query selection."""
        if not self.segments:
            return np.zeros((0, 0), np.float32)
        return np.concatenate([s.obs for s in self.segments.values()])

    def normalised(self) -> list[torch.Tensor]:
        """D0, D1, D2 as normalised observation tensors (rebuilt only after a change)."""
        if self._tensors is None:
            out = []
            for y in (0, 1, 2):
                parts = [s.obs for s in self.segments.values() if s.label == y]
                arr = np.concatenate(parts) if parts else np.zeros((0, 1), np.float32)
                arr = self._normalise(arr) if parts else arr
                out.append(torch.as_tensor(arr, dtype=torch.float32, device=self._device))
            self._tensors = out
        return self._tensors

    def embeddings(self, phi: torch.nn.Module, phi_version: int) -> list[torch.Tensor]:
        """φ(D0), φ(D1), φ(D2), encoded once per (φ version, label version)."""
        key = (phi_version, self.version)
        if key != self._cache_key:
            sets = self.normalised()
            sizes = [t.shape[0] for t in sets]
            with torch.no_grad():
                nonempty = [t for t in sets if t.shape[0] > 0]
                emb = phi(torch.cat(nonempty)) if nonempty else None
            out, start = [], 0
            for t, n in zip(sets, sizes, strict=True):
                if n == 0:
                    dim = emb.shape[1] if emb is not None else 1
                    out.append(torch.zeros((0, dim), device=t.device))
                else:
                    assert emb is not None  # some set is non-empty
                    out.append(emb[start : start + n])
                    start += n
            self._cache, self._cache_key = out, key
        return self._cache

    def state_dict(self) -> dict:
        return {qid: {"obs": s.obs, "label": s.label} for qid, s in self.segments.items()}

    def load_state_dict(self, state: dict) -> None:
        self.segments = {qid: LabelledSegment(kept(v["obs"]), int(v["label"])) for qid, v in state.items()}
        self.version += 1
        self._tensors = None
