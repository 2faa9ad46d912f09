"""The paper's guidance tasks (Appendix E, "Guidance task designs") with per-env geometry."""

from __future__ import annotations

import math
from dataclasses import dataclass

from collie.tasks.classes import BAD, GOOD, NEUTRAL
from collie.tasks.regions import Disc, HalfPlane, OutsideDisc, PitchBeyond, WedgeNorth
from collie.tasks.registry import EnvNotSupported, register_task
from collie.tasks.task import Task


@dataclass(frozen=True)
class Geometry:
    """Where the Range disc and the holes lie for one family of environments."""

    range_centre: tuple[float, float]
    range_radius: float
    hole_centres: tuple[tuple[float, float], ...]  # Hole: on the axes
    hole_radius: float
    hole_north_centres: tuple[tuple[float, float], ...]  # Hole-North: on the diagonals
    hole_north_radius: float


ANT_GEOMETRY = Geometry(
    range_centre=(0.0, 5.0),
    range_radius=20.0,
    hole_centres=((0.0, 20.0), (0.0, -20.0), (20.0, 0.0), (-20.0, 0.0)),
    hole_radius=12.0,
    hole_north_centres=((15.0, 15.0), (15.0, -15.0), (-15.0, -15.0), (-15.0, 15.0)),
    hole_north_radius=12.0,
)
# DMC bodies walk a smaller floor. Range and Hole follow the paper (Humanoid Hole) and
# REFERENCE_NOTES; Hole-North is not in the paper: (±6, ±6) r 4 as in the reference code.
DMC_GEOMETRY = Geometry(
    range_centre=(0.0, 2.0),
    range_radius=8.0,
    hole_centres=((0.0, 8.0), (0.0, -8.0), (8.0, 0.0), (-8.0, 0.0)),
    hole_radius=4.0,
    hole_north_centres=((6.0, 6.0), (6.0, -6.0), (-6.0, -6.0), (-6.0, 6.0)),
    hole_north_radius=4.0,
)
ENV_GEOMETRY: dict[str, Geometry] = {
    "point": ANT_GEOMETRY,
    "ant": ANT_GEOMETRY,
    "half_cheetah": ANT_GEOMETRY,  # its x only: the plane's tasks are refused (LINE_ENVS)
    "quadruped": DMC_GEOMETRY,
    "humanoid": DMC_GEOMETRY,
}


PITCHLESS_ENVS = ("point",)  # no body orientation: its pitch is undefined (nan), so Not-Flip would judge nothing
# A body that runs along x (its y is always 0): the paper defines only Right and Not-Flip for it; a
# wedge, disc or hole in x-y would judge a line through the plane, which no labeler could follow.
LINE_ENVS = ("half_cheetah",)
# the paper's tasks for the bodies North is not defined on (the first: a run's default; sweeps run all)
ENV_TASKS: dict[str, tuple[str, ...]] = {"half_cheetah": ("right", "not_flip"), "car": ("hazard",)}


def geometry(env: str) -> Geometry:
    if env not in ENV_GEOMETRY:
        raise EnvNotSupported(list(ENV_GEOMETRY))
    return ENV_GEOMETRY[env]


def plane_geometry(env: str) -> Geometry:
    """The geometry of a task drawn in the x-y plane, which a body moving along a line does not have."""
    if env in LINE_ENVS or env not in ENV_GEOMETRY:  # the car too: only the plane's bodies are named
        raise EnvNotSupported([e for e in ENV_GEOMETRY if e not in LINE_ENVS])
    return geometry(env)


def default_task(env: str) -> str:
    """The task a run of `env` gets when none is named."""
    return ENV_TASKS.get(env, ("north",))[0]


def _holes(centres: tuple[tuple[float, float], ...], radius: float) -> tuple[Disc, ...]:
    return tuple(Disc(c, radius, desirability=BAD) for c in centres)


def _fmt(centres: tuple[tuple[float, float], ...]) -> str:
    return ", ".join(f"({x:g}, {y:g})" for x, y in centres)


@register_task("north")
def north(env: str) -> Task:
    plane_geometry(env)
    return Task(
        "north",
        "Stay in the northern wedge: y ≥ |x| (north of both diagonals through the origin).",
        {BAD: "outside the wedge y ≥ |x|", NEUTRAL: "inside the wedge (safe)"},
        regions=(WedgeNorth(desirability=NEUTRAL),),
        background=BAD,
    )


@register_task("right")
def right(env: str) -> Task:
    geometry(env)
    return Task(
        "right",
        "Stay on the right: x ≥ 0.",
        {BAD: "left of x = 0", NEUTRAL: "at or right of x = 0 (safe)"},
        regions=(HalfPlane("left", desirability=BAD),),
    )


@register_task("range")
def range_(env: str) -> Task:
    g = plane_geometry(env)
    c, r = g.range_centre, g.range_radius
    return Task(
        "range",
        f"Stay within {r:g} of ({c[0]:g}, {c[1]:g}).",
        {BAD: "outside the safe circle", NEUTRAL: "inside the safe circle"},
        regions=(OutsideDisc(c, r, desirability=BAD),),
    )


@register_task("hole")
def hole(env: str) -> Task:
    g = plane_geometry(env)
    return Task(
        "hole",
        f"Keep out of the four holes of radius {g.hole_radius:g} at {_fmt(g.hole_centres)}.",
        {BAD: "inside a hole", NEUTRAL: "outside every hole (safe)"},
        regions=_holes(g.hole_centres, g.hole_radius),
    )


@register_task("not_flip")
def not_flip(env: str) -> Task:
    geometry(env)
    if env in PITCHLESS_ENVS:
        raise EnvNotSupported([e for e in ENV_GEOMETRY if e not in PITCHLESS_ENVS])
    return Task(
        "not_flip",
        "Do not flip over: the body's pitch must stay within ±90°.",
        {BAD: "flipped (|pitch| > 90°)", NEUTRAL: "upright enough (|pitch| ≤ 90°)"},
        regions=(PitchBeyond(math.pi / 2, desirability=BAD),),
    )


@register_task("range_north")
def range_north(env: str) -> Task:
    g = plane_geometry(env)
    c, r = g.range_centre, g.range_radius
    return Task(
        "range_north",
        f"Stay within {r:g} of ({c[0]:g}, {c[1]:g}); inside it, heading north (y ≥ |x|) is better.",
        {
            BAD: "outside the safe circle",
            NEUTRAL: "inside the circle but not north (y < |x|)",
            GOOD: "inside the circle and north (y ≥ |x|)",
        },
        regions=(WedgeNorth(desirability=GOOD), OutsideDisc(c, r, desirability=BAD)),
    )


@register_task("hole_north")
def hole_north(env: str) -> Task:
    g = plane_geometry(env)
    return Task(
        "hole_north",
        f"Keep out of the holes of radius {g.hole_north_radius:g} at {_fmt(g.hole_north_centres)};"
        " elsewhere, heading north (y ≥ |x|) is better.",
        {
            BAD: "inside a hole",
            NEUTRAL: "outside the holes but not north (y < |x|)",
            GOOD: "outside the holes and north (y ≥ |x|)",
        },
        regions=(WedgeNorth(desirability=GOOD), *_holes(g.hole_north_centres, g.hole_north_radius)),
    )


BUILTIN_TASKS: tuple[str, ...] = ("north", "right", "range", "hole", "not_flip", "range_north", "hole_north")
