"""The scripted oracle teacher: labels a segment from the task rule, optionally with the
paper's R_error noise (§ "Evaluation under noisy feedback": within R_error of a safety boundary,
state labels are drawn at random between neutral and bad). Numpy only.
"""

from __future__ import annotations

import numpy as np

from collie.labels import Label
from collie.tasks import BAD, CLASSES, GOOD, NEUTRAL, Task


def segment_label(classes: np.ndarray) -> Label:
    """A segment's label from its states' classes: bad if any state is bad, good if all are
    good, else neutral (the teacher rule of Appendix E)."""
    classes = np.asarray(classes).reshape(-1)
    if classes.size == 0:
        raise ValueError("a segment needs at least one state")
    if not np.isin(classes, CLASSES).all():
        raise ValueError(f"state classes must be in {CLASSES}")
    if (classes == BAD).any():
        return BAD
    return GOOD if (classes == GOOD).all() else NEUTRAL


class OracleTeacher:
    """Labels segments with `task`; `noise_band` is R_error (0 = exact labels)."""

    def __init__(self, task: Task, noise_band: float = 0.0, seed: int = 0) -> None:
        if not noise_band >= 0:
            raise ValueError(f"noise_band must be ≥ 0, got {noise_band}")
        self.task = task
        self.noise_band = float(noise_band)
        self.rng = np.random.default_rng(seed)

    def state_labels(self, xy: np.ndarray, pitch: np.ndarray | None = None) -> np.ndarray:
        """(H,) int8 per-state labels as this teacher sees them (noised inside the band)."""
        classes = self.task.classify(xy, pitch)
        if self.noise_band > 0:
            near = self.task.boundary_distance(xy, pitch) < self.noise_band
            # One draw per noised state, so a given seed and input sequence is reproducible.
            classes[near] = self.rng.choice(np.array([NEUTRAL, BAD], dtype=np.int8), size=int(near.sum()))
        return classes

    def label(self, xy: np.ndarray, pitch: np.ndarray | None = None) -> Label:
        """The segment label for states xy (H, 2), pitch (H,)."""
        return segment_label(self.state_labels(xy, pitch))
