"""The label a person (or the oracle) gives a segment, and the per-state class g(s) of a task rule:
one IntEnum for both, so 0/1/2 and their names are written once. Skip is not a label."""

from __future__ import annotations

from enum import IntEnum


class Label(IntEnum):
    BAD = 0
    NEUTRAL = 1
    GOOD = 2

    @property
    def word(self) -> str:
        """The lower-case name people read ("bad", "neutral", "good")."""
        return self.name.lower()
