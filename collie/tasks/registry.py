"""Task registry: `@register_task("name")` on a factory `f(env) -> Task` makes it usable by name.

A task whose scenery is drawn at random once per experiment (the car's hazards) registers with
`layout=True`; its factory is `f(env, layout_seed) -> Task` and `get_task` then requires the
experiment's `layout_seed`, so a teacher can never judge against another run's layout.
"""

from __future__ import annotations

from collections.abc import Callable

from collie.tasks.task import Task

TaskFactory = Callable[..., Task]

_FACTORIES: dict[str, TaskFactory] = {}
_LAYOUT_TASKS: set[str] = set()


def register_task(name: str, *, replace: bool = False, layout: bool = False) -> Callable[[TaskFactory], TaskFactory]:
    """Decorator registering `factory(env) -> Task` (or `factory(env, layout_seed)` with `layout`)
    under `name` (a CLI name)."""

    def decorate(factory: TaskFactory) -> TaskFactory:
        if name in _FACTORIES and not replace:
            raise ValueError(f"task {name!r} is already registered (pass replace=True to override)")
        _FACTORIES[name] = factory
        (_LAYOUT_TASKS.add if layout else _LAYOUT_TASKS.discard)(name)
        return factory

    return decorate


def task_names() -> tuple[str, ...]:
    """All registered task names, in registration order (built-ins first)."""
    return tuple(_FACTORIES)


def has_layout(name: str) -> bool:
    """Whether task `name` depends on a per-experiment random layout (needs `layout_seed`)."""
    return name in _LAYOUT_TASKS


def get_task(name: str, env: str = "point", layout_seed: int | None = None) -> Task:
    """The task `name` with the geometry of environment `env`. `layout_seed` (the experiment
    seed) places random scenery; tasks without any ignore it, tasks with some require it."""
    factory = _FACTORIES.get(name)
    if factory is None:
        raise ValueError(f"unknown task {name!r}; valid tasks: {', '.join(task_names())}")
    if name not in _LAYOUT_TASKS:
        return factory(env)
    if layout_seed is None:
        raise ValueError(
            f"task {name!r} places its scenery at random per experiment: pass layout_seed (the run's seed)"
        )
    return factory(env, int(layout_seed))
