"""The Safety-Gym Hazard task (paper, Appendix E): being inside any hazard is bad.

Eight hazards of radius 0.2 lie at random inside the square ±1.5, drawn once per experiment from
its seed and fixed for the run, as in the paper's customised CarGoal1. The car env reads the same
layout (`hazard_layout`), so its lidar, its scene and the teacher always agree. Numpy only.
"""

from __future__ import annotations

import numpy as np

from collie.tasks.classes import BAD, NEUTRAL
from collie.tasks.regions import Disc
from collie.tasks.registry import EnvNotSupported, register_task
from collie.tasks.task import Task

HAZARD_COUNT = 8
HAZARD_RADIUS = 0.2
PLACEMENT_EXTENT = 1.5  # every hazard lies wholly inside [−1.5, 1.5]²
START_CLEARANCE = 0.15  # the car starts at the origin, never already inside a hazard
HAZARD_ENVS = ("car",)


def hazard_layout(
    layout_seed: int, count: int = HAZARD_COUNT, radius: float = HAZARD_RADIUS, extent: float = PLACEMENT_EXTENT
) -> np.ndarray:
    """(count, 2) hazard centres for an experiment seed: uniform, non-overlapping, off the start.

    Rejection sampling from the seed's own generator, so the layout depends on nothing else."""
    rng = np.random.default_rng([layout_seed, 0x4A2])  # a stream no other use of the seed shares
    centres: list[np.ndarray] = []
    for _ in range(100_000):
        c = rng.uniform(-(extent - radius), extent - radius, size=2)
        clear_of_start = np.hypot(*c) >= radius + START_CLEARANCE
        if clear_of_start and all(np.hypot(*(c - o)) >= 2 * radius for o in centres):
            centres.append(c)
            if len(centres) == count:
                return np.array(centres)
    raise RuntimeError(f"could not place {count} hazards of radius {radius} inside ±{extent}")


@register_task("hazard", layout=True)
def hazard(env: str, layout_seed: int) -> Task:
    if env not in HAZARD_ENVS:
        raise EnvNotSupported(HAZARD_ENVS)
    centres = hazard_layout(layout_seed)
    return Task(
        "hazard",
        f"Keep out of the {len(centres)} hazards (blue discs of radius {HAZARD_RADIUS:g}).",
        {BAD: "inside a hazard", NEUTRAL: "outside every hazard (safe)"},
        regions=tuple(Disc((float(x), float(y)), HAZARD_RADIUS, desirability=BAD) for x, y in centres),
        background=NEUTRAL,
    )
