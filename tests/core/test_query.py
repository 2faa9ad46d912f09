"""Algorithm 2: the active query strategies."""

import numpy as np
import torch

from trainer.query import particle_entropy, select_queries


def test_particle_entropy_is_the_papers_estimate():
    labelled = torch.tensor([[0.0], [1.0], [3.0]])
    h = particle_entropy(torch.tensor([[0.0]]), labelled, k=2)
    assert torch.allclose(h, torch.log1p(torch.tensor([(0 + 1) / 2])))


def test_entropy_prefers_segments_far_from_labelled_states():
    rng = np.random.default_rng(0)
    labelled = rng.normal(0, 0.1, size=(40, 2))
    near = rng.normal(0, 0.1, size=(8, 5, 2))
    far = rng.normal(0, 0.1, size=(2, 5, 2)) + np.array([[[6.0, 6.0]], [[-7.0, 4.0]]])
    windows = np.concatenate([near[:4], far[:1], near[4:], far[1:]])  # far ones at index 4 and 9
    chosen, scores = select_queries(windows, 2, "entropy", labelled, k=5, rng=rng)
    assert sorted(chosen.tolist()) == [4, 9]
    assert scores[[4, 9]].min() > scores[np.r_[0:4, 5:9]].max()


def test_first_session_and_uniform_strategy_choose_without_scores():
    rng = np.random.default_rng(1)
    windows = rng.normal(size=(10, 5, 2))
    chosen, scores = select_queries(windows, 3, "entropy", np.zeros((0, 2)), k=5, rng=rng)
    assert len(set(chosen.tolist())) == 3 and not scores.any()
    chosen, _ = select_queries(windows, 3, "uniform", rng.normal(size=(4, 2)), k=5, rng=rng)
    assert len(set(chosen.tolist())) == 3


def test_latent_and_uncertainty_strategies_use_phi():
    rng = np.random.default_rng(2)
    labelled = rng.normal(size=(10, 2))
    windows = rng.normal(size=(6, 4, 2))
    windows[3] += 50.0

    def phi(x: torch.Tensor) -> torch.Tensor:
        return x * 3

    chosen, _ = select_queries(windows, 1, "latent", labelled, k=3, rng=rng, phi=phi)
    assert chosen.tolist() == [3]
    emb = [phi(torch.tensor(labelled[i::3], dtype=torch.float32)) for i in range(3)]
    chosen, scores = select_queries(windows, 2, "uncertainty", labelled, k=3, rng=rng, phi=phi, labelled_emb=emb)
    assert len(chosen) == 2 and np.all(scores >= 0) and 3 not in chosen.tolist()  # far away → confident
