"""w(s) (Eq. 8), its nearest-neighbour reading (Proposition 1), smoothing, labelled sets."""

import math

import numpy as np
import pytest
import torch

from trainer.guidance import LabelledSets, class_distances, guidance_weight, smoothing_beta


def eq8_by_hand(z: np.ndarray, sets: list[np.ndarray]) -> np.ndarray:
    out = []
    for s in z:
        d = [min(np.linalg.norm(s - p) for p in d_i) if len(d_i) else 1e10 for d_i in sets]
        e = [math.exp(-x) for x in d]
        out.append(sum(y * ei for y, ei in zip((0, 1, 2), e, strict=True)) / sum(e))
    return np.array(out)


def test_weight_matches_equation_8_on_hand_built_cases():
    sets = [np.array([[0.0, 0.0]]), np.array([[3.0, 0.0], [0.0, 5.0]]), np.array([[10.0, 10.0]])]
    z = np.array([[0.0, 0.0], [3.0, 0.1], [9.0, 9.0], [5.0, 5.0]])
    got = guidance_weight(torch.tensor(z), [torch.tensor(s) for s in sets]).numpy()
    np.testing.assert_allclose(got, eq8_by_hand(z, sets), rtol=1e-6)
    # at a bad labelled state w ≈ 0.05 (the others are ≥ 3 away), near good ≈ 2
    assert got[0] < 0.1 and got[2] > 1.5


def test_weight_is_one_without_labels_and_empty_classes_are_far():
    z = torch.randn(5, 2)
    empty = [torch.zeros(0, 2)] * 3
    assert torch.equal(guidance_weight(z, empty), torch.ones(5))
    only_bad = [torch.zeros(1, 2), torch.zeros(0, 2), torch.zeros(0, 2)]
    assert torch.allclose(guidance_weight(z, only_bad), torch.zeros(5))
    assert class_distances(z, only_bad)[0, 1].item() == pytest.approx(1e10)


def test_argmax_equals_one_nearest_neighbour_classifier():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(60, 3))
    labels = rng.integers(0, 3, size=60)
    sets = [torch.tensor(pts[labels == y]) for y in range(3)]
    query = torch.tensor(rng.normal(size=(500, 3)))
    probs = torch.softmax(-class_distances(query, sets), dim=1)
    nn_class = labels[torch.cdist(query, torch.tensor(pts)).argmin(dim=1).numpy()]
    assert np.array_equal(probs.argmax(dim=1).numpy(), nn_class)


def test_smoothing_beta_schedule():
    # before the first feedback: pure METRA
    assert smoothing_beta(10, None, 8000, 5) == 1.0
    assert smoothing_beta(1999, 2000, 8000, 5) == 1.0
    # from the first feedback, linear to 0 over span / k_β epochs
    assert smoothing_beta(2000, 2000, 8000, 5) == 1.0
    assert smoothing_beta(2800, 2000, 8000, 5) == pytest.approx(0.5)
    assert smoothing_beta(3600, 2000, 8000, 5) == 0.0
    assert smoothing_beta(9000, 2000, 8000, 5) == 0.0
    # k_β = 0 stays unsupervised, k_β = ∞ is guided at once
    assert smoothing_beta(9000, 2000, 8000, 0) == 1.0
    assert smoothing_beta(2000, 2000, 8000, math.inf) == 0.0


def test_labelled_sets_revisions_and_embedding_cache():
    sets = LabelledSets(lambda x: x * 2, torch.device("cpu"))
    sets.set("a", np.ones((3, 2)), 0)
    sets.set("b", np.zeros((3, 2)), 2)
    assert sets.counts() == (3, 0, 3)
    calls = []

    def phi(x: torch.Tensor) -> torch.Tensor:
        calls.append(x.shape[0])
        return x

    e1 = sets.embeddings(phi, 1)
    sets.embeddings(phi, 1)  # same φ version and labels: cached
    assert calls == [6]
    assert torch.equal(e1[0], torch.full((3, 2), 2.0))  # normalised before encoding
    sets.set("a", np.ones((3, 2)), 1)  # undo + relabel moves the whole segment
    assert sets.counts() == (0, 3, 3)
    sets.embeddings(phi, 1)
    sets.embeddings(phi, 2)
    assert calls == [6, 6, 6]
    sets.set("b", np.zeros((3, 2)), None)
    assert sets.counts() == (0, 3, 0)
    with pytest.raises(ValueError, match="label must be"):
        sets.set("c", np.zeros((1, 2)), 3)


@pytest.mark.parametrize("env", ["point", "quadruped"])  # quadruped: uint8 frames, normalised on the device
def test_guidance_along_a_rollout_equals_the_host_normalised_path(tmp_path, env):
    """The evaluations' w_e(s) normalises its frames a part at a time on the device, as the batches
    are (no float copy of every frame on the host): the same numbers, bit for bit, on the CPU."""
    from trainer.config import make_config
    from trainer.loop import Trainer

    cfg = make_config("smoke", env, out=str(tmp_path), eval_trajectories=2, episodes_per_epoch=2)
    trainer = Trainer(cfg, progress=False)
    trainer.epoch = 1
    trainer.collect_epoch()
    r = trainer.replay
    for q, label in enumerate((0, 1, 2)):
        trainer.labelled.set(f"q{q}", r.obs[q % r.count, q : q + 3], label)
    trainer.first_feedback_epoch = trainer.epoch - cfg.feedback_every  # guidance on: β < 1
    obs = r.obs[: r.count, ::4]
    got = trainer.guidance_along(obs)
    emb = trainer.labelled.embeddings(trainer.agent.phi, trainer.agent.phi_version)
    with torch.no_grad():
        flat = torch.as_tensor(trainer.normalise(obs.reshape(-1, *obs.shape[2:])), dtype=torch.float32)
        w = guidance_weight(trainer.agent.phi(flat), emb)
    beta = trainer.beta()
    assert got is not None and beta < 1 and obs.dtype == (np.uint8 if env == "quadruped" else np.float32)
    np.testing.assert_array_equal(got, ((1 - beta) * w + beta).numpy().astype(np.float64).reshape(obs.shape[:2]))
    trainer.env.close()
