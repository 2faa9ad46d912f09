"""Guidance tasks: per-state desirability g(s) ∈ {0 bad, 1 neutral, 2 good} (numpy only).

Shared by the trainer (Oracle baseline, metrics), the teacher (labels) and UIs (drawing regions).
Numpy only, plus the pydantic wire form of a rule (collie.task_schemas): no torch, no MuJoCo.
See docs/tasks.md for the rules, boundary conventions and how to add a task.
"""

from collie.tasks.builtin import BUILTIN_TASKS as TASK_NAMES
from collie.tasks.builtin import ENV_GEOMETRY, ENV_TASKS, Geometry, default_task
from collie.tasks.classes import BAD, CLASS_NAMES, CLASSES, GOOD, NEUTRAL
from collie.tasks.definition import NotDeclarative, from_definition, task_for_run, to_definition
from collie.tasks.hazard import HAZARD_RADIUS, hazard_layout
from collie.tasks.regions import Disc, HalfPlane, OutsideDisc, PitchBeyond, Polygon, Region, WedgeNorth, wrap_angle
from collie.tasks.registry import get_task, has_layout, register_task, task_names, tasks_for
from collie.tasks.task import Distance, Rule, Task

__all__ = [
    "BAD",
    "CLASSES",
    "CLASS_NAMES",
    "ENV_GEOMETRY",
    "ENV_TASKS",
    "GOOD",
    "HAZARD_RADIUS",
    "NEUTRAL",
    "TASK_NAMES",
    "Disc",
    "Distance",
    "Geometry",
    "HalfPlane",
    "NotDeclarative",
    "OutsideDisc",
    "PitchBeyond",
    "Polygon",
    "Region",
    "Rule",
    "Task",
    "WedgeNorth",
    "default_task",
    "from_definition",
    "get_task",
    "has_layout",
    "hazard_layout",
    "register_task",
    "task_for_run",
    "task_names",
    "tasks_for",
    "to_definition",
    "wrap_angle",
]
