"""The classifier baselines (DoDont*, DDG*) learn a separable toy labelling from labelled segments,
and refit only when the labelled set changes."""

import numpy as np
import torch

from trainer.config import make_config
from trainer.guidance import LabelledSets
from trainer.instruction import InstructionClassifier


def toy_label(x: np.ndarray) -> np.ndarray:
    """bad left of −1, neutral in between, good right of +1 (along the first coordinate)."""
    return np.where(x[:, 0] < -1, 0, np.where(x[:, 0] > 1, 2, 1))


def toy_segments(rng: np.random.Generator, n: int, h: int = 10) -> list[tuple[np.ndarray, int]]:
    segs = []
    for _ in range(n):
        label = int(rng.integers(0, 3))
        centre = {0: -3.0, 1: 0.0, 2: 3.0}[label]
        obs = rng.normal(0, 0.5, size=(h, 4)).astype(np.float32)
        obs[:, 0] = np.clip(centre + rng.normal(0, 0.5, size=h), [-9, -0.9, 1.1][label], [-1.1, 0.9, 9][label])
        segs.append((obs, label))
    return segs


def test_instruction_classifier_learns_a_separable_labelling():
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    cfg = make_config("smoke", "point", hidden=64, lr=1e-2, classifier_steps=300)
    labelled = LabelledSets(lambda x: x, torch.device("cpu"))
    for i, (obs, label) in enumerate(toy_segments(rng, 30)):
        labelled.set(f"q{i}", obs, label)
    clf = InstructionClassifier(4, cfg, torch.device("cpu"))
    assert not clf.trained
    assert clf.refresh(labelled) and clf.trained
    test = np.concatenate([obs for obs, _ in toy_segments(np.random.default_rng(1), 60)])
    w = 2 * clf.prob(torch.as_tensor(test)).numpy()  # DoDont*'s weight: 0 bad, 1 neutral, 2 good
    assert (np.rint(w) == toy_label(test)).mean() >= 0.95
    # desirable vs undesirable, the DoDont reading
    assert ((w > 0.5) == (toy_label(test) > 0)).mean() >= 0.98


def test_refits_only_when_the_labels_change():
    cfg = make_config("smoke", "point", hidden=16, classifier_steps=5)
    labelled = LabelledSets(lambda x: x, torch.device("cpu"))
    clf = InstructionClassifier(4, cfg, torch.device("cpu"))
    assert not clf.refresh(labelled)  # nothing labelled: nothing to fit, w stays 1
    labelled.set("a", np.zeros((3, 4), np.float32), 0)
    assert clf.refresh(labelled)
    assert not clf.refresh(labelled)
    labelled.set("a", np.zeros((3, 4), np.float32), 1)  # a revision (undo + relabel)
    assert clf.refresh(labelled)
    state = clf.state_dict()
    other = InstructionClassifier(4, cfg, torch.device("cpu"))
    other.load_state_dict(state)
    assert not other.refresh(labelled)  # a resumed run does not refit what it already fitted
