"""A guidance task: the per-state desirability rule g(s) ∈ {bad, neutral, good} (Appendix E).

A task is either painted from regions over a background class (then its boundary distance is
derived from the same shapes, so drawings, labels and the noise band always agree), or given as a
`rule` function (then pass `distance` too if the R_error noise band is wanted).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from collie.tasks.classes import BAD, CLASSES, GOOD, NEUTRAL
from collie.tasks.regions import Region

Rule = Callable[[np.ndarray, np.ndarray | None], np.ndarray]
"""(xy (N, 2), pitch (N,) or None) -> (N,) classes in {0, 1, 2}."""
Distance = Callable[[np.ndarray, np.ndarray | None], np.ndarray]
"""(xy (N, 2), pitch (N,) or None) -> (N,) distance to the nearest safety boundary."""

_DEFAULT_MEANING = {
    BAD: "a state the labeler wants avoided",
    NEUTRAL: "an acceptable state",
    GOOD: "a state the labeler wants more of",
}


@dataclass(frozen=True)
class Task:
    """A named desirability rule. `regions` are painted in order over `background`."""

    name: str
    description: str  # plain language for a labeler
    meaning: dict[int, str] = field(default_factory=dict, hash=False)  # one line per class
    can_be_good: bool = False  # forced True when a region or the background is GOOD
    regions: tuple[Region, ...] = ()
    background: int = NEUTRAL
    uses_pitch: bool = False  # forced True when a region depends on pitch
    rule: Rule | None = field(default=None, repr=False)  # overrides painting the regions
    distance: Distance | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.background not in CLASSES:
            raise ValueError(f"background must be one of {CLASSES}, got {self.background!r}")
        painted = {self.background, *(r.desirability for r in self.regions)}
        object.__setattr__(self, "regions", tuple(self.regions))
        object.__setattr__(self, "can_be_good", self.can_be_good or (self.rule is None and GOOD in painted))
        object.__setattr__(self, "uses_pitch", self.uses_pitch or any(r.uses_pitch for r in self.regions))
        defaults = dict(_DEFAULT_MEANING)
        if not self.can_be_good:
            defaults[GOOD] = "not used: this task never calls a state good"
        object.__setattr__(self, "meaning", {**defaults, **self.meaning})

    def classify(self, xy: np.ndarray, pitch: np.ndarray | None = None) -> np.ndarray:
        """g(s) for each state: (N,) int8 in {0 bad, 1 neutral, 2 good}."""
        xy, pitch = self._check(xy, pitch)
        if self.rule is not None:
            classes = np.asarray(self.rule(xy, pitch))
            if classes.shape != (len(xy),) or not np.isin(classes, CLASSES).all():
                raise ValueError(f"task {self.name!r}: rule must return ({len(xy)},) values in {CLASSES}")
            return classes.astype(np.int8)
        classes = np.full(len(xy), self.background, dtype=np.int8)
        for region in self.regions:
            classes[region.contains(xy, pitch)] = region.desirability
        return classes

    def boundary_distance(self, xy: np.ndarray, pitch: np.ndarray | None = None) -> np.ndarray:
        """(N,) distance to the nearest safety boundary (bad vs not bad), in position units, or
        radians for pitch rules; inf where the task has no safety boundary.

        Derived from the regions whose edge can separate bad from not bad: exact when those
        edges do not overlap (all built-in tasks), otherwise a lower bound (a wider noise band).
        """
        xy, pitch = self._check(xy, pitch)
        if self.distance is not None:
            return np.asarray(self.distance(xy, pitch), dtype=float)
        if self.rule is not None:
            raise NotImplementedError(
                f"task {self.name!r} is defined by a rule function; give it `distance=` to use a noise band"
            )
        result = np.full(len(xy), np.inf)
        for region in self._safety_regions():
            result = np.minimum(result, np.abs(region.signed_distance(xy, pitch)))
        return result

    def _safety_regions(self) -> list[Region]:
        """Regions painted over something of the other safety side (bad vs not bad)."""
        below = {self.background == BAD}
        relevant = []
        for region in self.regions:
            is_bad = region.desirability == BAD
            if (not is_bad) in below:
                relevant.append(region)
            below.add(is_bad)
        return relevant

    def _check(self, xy: np.ndarray, pitch: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        xy = np.asarray(xy, dtype=float)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy must have shape (N, 2), got {xy.shape}")
        if pitch is not None:
            pitch = np.asarray(pitch, dtype=float).reshape(-1)
            if len(pitch) != len(xy):
                raise ValueError(f"pitch has {len(pitch)} values for {len(xy)} states")
        elif self.uses_pitch:
            raise ValueError(f"task {self.name!r} needs the pitch angle of each state")
        return xy, pitch

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description for UIs: draw `background`, then each region in order."""
        return {
            "name": self.name,
            "description": self.description,
            "meaning": {str(k): v for k, v in sorted(self.meaning.items())},
            "can_be_good": self.can_be_good,
            "uses_pitch": self.uses_pitch,
            "background": self.background,
            "regions": [region.to_dict() for region in self.regions],
        }
