"""Task registry: `@register_task("name")` on a factory `f(env) -> Task` makes it usable by name."""

from __future__ import annotations

from collections.abc import Callable

from collie.tasks.task import Task

TaskFactory = Callable[[str], Task]

_FACTORIES: dict[str, TaskFactory] = {}


def register_task(name: str, *, replace: bool = False) -> Callable[[TaskFactory], TaskFactory]:
    """Decorator registering `factory(env) -> Task` under `name` (a CLI name)."""

    def decorate(factory: TaskFactory) -> TaskFactory:
        if name in _FACTORIES and not replace:
            raise ValueError(f"task {name!r} is already registered (pass replace=True to override)")
        _FACTORIES[name] = factory
        return factory

    return decorate


def task_names() -> tuple[str, ...]:
    """All registered task names, in registration order (built-ins first)."""
    return tuple(_FACTORIES)


def get_task(name: str, env: str = "point") -> Task:
    """The task `name` with the geometry of environment `env`."""
    factory = _FACTORIES.get(name)
    if factory is None:
        raise ValueError(f"unknown task {name!r}; valid tasks: {', '.join(task_names())}")
    return factory(env)
