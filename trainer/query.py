"""Active query selection (Algorithm 2) and the strategies of the query ablation (Appendix F).

Candidates are random H-state windows from the trajectory history. With no labels yet, M of them
are taken uniformly. Otherwise N_c candidates are scored and the top M kept:
  entropy     I(σ) = Σ_{s∈σ} log(1 + (1/k)·Σ_j ‖s − s^(j)‖)  in normalised observation space (Eq. 12)
  latent      the same in φ-space (COLLIE-φ)
  uncertainty Σ_{s∈σ} H[softmax(−d_φ(s, D_i))]  (entropy of the guidance classifier, Eq. 13)
  uniform     no scoring
s^(j) is the j-th nearest labelled state (any class). The reference scores with the distance to the
k-th neighbour only; we follow the paper's mean over the k nearest.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from trainer.guidance import class_distances


def particle_entropy(states: torch.Tensor, labelled: torch.Tensor, k: int) -> torch.Tensor:
    """H_state(s) ≈ log(1 + (1/k)·Σ_{j≤k} ‖s − s^(j)‖) against the labelled set (Eq. 12)."""
    k = min(k, labelled.shape[0])
    d = torch.cdist(states, labelled)
    return torch.log1p(d.topk(k, dim=1, largest=False).values.mean(dim=1))


def classifier_entropy(z: torch.Tensor, labelled_emb: list[torch.Tensor]) -> torch.Tensor:
    """H_w(s) = entropy of softmax(−d_φ(s, D_i)) (Eq. 13)."""
    p = torch.softmax(-class_distances(z, labelled_emb), dim=1)
    return -(p * torch.log(p.clamp_min(1e-12))).sum(dim=1)


def select_queries(
    windows: np.ndarray,  # (N_c, H, d) normalised candidate states
    m: int,
    strategy: str,
    labelled: np.ndarray,  # (n, d) normalised labelled states, any class
    k: int,
    rng: np.random.Generator,
    phi: Callable[[torch.Tensor], torch.Tensor] | None = None,
    labelled_emb: list[torch.Tensor] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2: indices of the M chosen candidates and every candidate's score I(σ)."""
    n_c, h, d = windows.shape
    if strategy == "uniform" or labelled.shape[0] == 0:
        return rng.choice(n_c, size=m, replace=False), np.zeros(n_c)
    flat = torch.as_tensor(windows.reshape(n_c * h, d), dtype=torch.float32)
    ref = torch.as_tensor(labelled, dtype=torch.float32)
    with torch.no_grad():
        if strategy == "entropy":
            per_state = particle_entropy(flat, ref, k)
        elif strategy == "latent":
            if phi is None:
                raise ValueError("the latent strategy needs φ")
            per_state = particle_entropy(phi(flat), phi(ref), k)
        elif strategy == "uncertainty":
            if phi is None or labelled_emb is None:
                raise ValueError("the uncertainty strategy needs φ and the labelled embeddings")
            per_state = classifier_entropy(phi(flat), [e.cpu() for e in labelled_emb])
        else:
            raise ValueError(f"unknown query strategy {strategy!r}")
    scores = per_state.reshape(n_c, h).sum(dim=1).numpy()  # I(σ) = Σ_{s∈σ} H(s)
    return np.argsort(-scores, kind="stable")[:m], scores
