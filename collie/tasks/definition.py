"""A Task ⇄ its wire form (collie.task_schemas.TaskDefinition), and the rule of a run as the service
holds it: every process judges and draws from that copy, never from its own files or registry, so
no two processes can disagree about a run's rule.
"""

from __future__ import annotations

from typing import Any, Literal, Protocol, cast

from collie.task_schemas import (
    DiscSpec,
    HalfPlaneSpec,
    OutsideDiscSpec,
    PitchLimitSpec,
    PolygonSpec,
    RegionSpec,
    TaskDefinition,
    TaskMeaning,
    WedgeNorthSpec,
)
from collie.tasks.classes import CLASS_NAMES
from collie.tasks.regions import Disc, HalfPlane, OutsideDisc, PitchBeyond, Polygon, Region, WedgeNorth
from collie.tasks.registry import get_task
from collie.tasks.task import Task


class NotDeclarative(ValueError):
    """The task is a rule function: it cannot travel as data."""


def region_spec(region: Region) -> RegionSpec:
    d = cast(Literal[0, 1, 2], region.desirability)  # a Region's class is 0, 1 or 2 (checked where it is made)
    if isinstance(region, OutsideDisc):
        return OutsideDiscSpec(kind="outside_disc", desirability=d, centre=list(region.centre), radius=region.radius)
    if isinstance(region, Disc):
        return DiscSpec(kind="disc", desirability=d, centre=list(region.centre), radius=region.radius)
    if isinstance(region, WedgeNorth):
        return WedgeNorthSpec(kind="wedge_north", desirability=d, apex=list(region.apex))
    if isinstance(region, HalfPlane):
        return HalfPlaneSpec(kind=region.kind, desirability=d, x0=region.x0)  # type: ignore[arg-type]  # kind: 'halfplane_left' or '_right'
    if isinstance(region, PitchBeyond):
        return PitchLimitSpec(kind="pitch_beyond", desirability=d, limit=region.limit)
    if isinstance(region, Polygon):
        return PolygonSpec(kind="polygon", desirability=d, vertices=[list(p) for p in region.vertices])
    raise NotDeclarative(f"region {type(region).__name__} has no declarative form")


def to_definition(task: Task, source: str = "") -> TaskDefinition:
    """The task as data. A task given as a `rule` function cannot be written down: NotDeclarative."""
    if task.rule is not None:
        raise NotDeclarative(
            f"task {task.name!r} is a rule function; a run's rule must be painted from regions so that the "
            "service can hold it (see docs/tasks.md)"
        )
    meaning = TaskMeaning(**{CLASS_NAMES[k]: v for k, v in task.meaning.items()})
    return TaskDefinition(
        name=task.name,
        description=task.description,
        meaning=meaning,
        background=task.background,  # type: ignore[arg-type]  # a Task background is 0, 1 or 2
        regions=[region_spec(r) for r in task.regions],
        source=source,
    )


def region_of(spec: RegionSpec) -> Region:
    d = spec.desirability
    if isinstance(spec, DiscSpec):
        return Disc((spec.centre[0], spec.centre[1]), spec.radius, desirability=d)
    if isinstance(spec, OutsideDiscSpec):
        return OutsideDisc((spec.centre[0], spec.centre[1]), spec.radius, desirability=d)
    if isinstance(spec, WedgeNorthSpec):
        return WedgeNorth(desirability=d, apex=(spec.apex[0], spec.apex[1]))
    if isinstance(spec, HalfPlaneSpec):
        return HalfPlane("left" if spec.kind == "halfplane_left" else "right", spec.x0, desirability=d)
    if isinstance(spec, PitchLimitSpec):
        return PitchBeyond(spec.limit, desirability=d)
    return Polygon(tuple((p[0], p[1]) for p in spec.vertices), desirability=d)


def from_definition(definition: TaskDefinition) -> Task:
    """The Task a definition describes (classes, boundary distance and drawing all follow from it)."""
    return Task(
        definition.name,
        definition.description,
        definition.meaning.by_class(),
        regions=tuple(region_of(r) for r in definition.regions),
        background=definition.background,
    )


class RunLike(Protocol):
    task: str
    env: str
    config: dict[str, Any]
    task_definition: TaskDefinition | None
    instruction: str | None


def task_for_run(run: RunLike) -> Task | None:
    """The rule of a run as the service holds it; None for a run with only an instruction.

    Runs stored before definitions travelled carry none: their built-in task is looked up by name
    (ValueError when there is no such task)."""
    if run.task_definition is not None:
        return from_definition(run.task_definition)
    if run.instruction is not None:
        return None
    seed = run.config.get("seed") if isinstance(run.config, dict) else None
    return get_task(run.task, run.env, layout_seed=seed if isinstance(seed, int) else None)
