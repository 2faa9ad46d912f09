"""DoDont* — the online variant of DoDont (Kim et al., 2024) used as a baseline (Section 5.1, App. E).

DoDont weights METRA's distance by an instruction network's probability that a transition is
"do" rather than "don't". With the substitution φ′ = φ/w of the paper's Appendix (the same one
that turns COLLIE's Eq. 6 into Eq. 9), that weight multiplies the reward:
    J^φ = E[ w·(φ(s′) − φ(s))ᵀz + λ·min(ε, 1 − ‖φ(s′) − φ(s)‖²) ]      (Eq. 9)
    r(s, z, s′) = w·(φ(s′) − φ(s))ᵀz                                    (Eq. 11)
with w = 2·ψ(s′) for DoDont* instead of Eq. 8 — ψ the instruction classifier trained incrementally
on the labelled segments (trainer/instruction.py), scaled to COLLIE's 0 (bad) … 2 (good) range.
No labels yet → w ≡ 1 (METRA), as for COLLIE before its first feedback session; no smoothing.
"""

from __future__ import annotations

import numpy as np
import torch

from trainer.instruction import InstructionClassifier
from trainer.metra import WeightFn

WEIGHT_SCALE = 2.0  # ψ ∈ (0, 1) → w ∈ (0, 2), the range of Eq. 8


def dodont_weight(
    classifier: InstructionClassifier, obs: np.ndarray | torch.Tensor, device: torch.device
) -> WeightFn | None:
    """w = 2·ψ(s) for the batch's normalised states (s′ by default: `--w-at`); None before any label.
    A float32 tensor already on `device` (the batch's own) is used as it is."""
    if not classifier.trained:
        return None
    w = WEIGHT_SCALE * classifier.prob(torch.as_tensor(obs, dtype=torch.float32, device=device))
    return lambda _phi_s, _phi_next: w
