"""Per-state desirability classes g(s) ∈ {0, 1, 2} shared by every task, teacher and metric."""

from __future__ import annotations

BAD, NEUTRAL, GOOD = 0, 1, 2
CLASSES: tuple[int, int, int] = (BAD, NEUTRAL, GOOD)
CLASS_NAMES: dict[int, str] = {BAD: "bad", NEUTRAL: "neutral", GOOD: "good"}
