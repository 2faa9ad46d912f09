"""Per-state desirability classes g(s) ∈ {0, 1, 2} shared by every task, teacher and metric: the
values of collie.labels.Label."""

from __future__ import annotations

from collie.labels import Label

BAD, NEUTRAL, GOOD = Label.BAD, Label.NEUTRAL, Label.GOOD
CLASSES: tuple[int, ...] = tuple(int(c) for c in Label)  # plain ints: they print as 0, 1, 2 in errors
CLASS_NAMES: dict[int, str] = {c: c.word for c in Label}
