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


class EnvNotSupported(ValueError):
    """A task factory's answer for an env its rule is not defined on (the car has no North wedge)."""

    def __init__(self, envs: tuple[str, ...] | list[str]) -> None:
        super().__init__(", ".join(envs))  # the envs it is defined for


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
    if name in _LAYOUT_TASKS and layout_seed is None:
        raise ValueError(
            f"task {name!r} places its scenery at random per experiment: pass layout_seed (the run's seed)"
        )
    try:
        return factory(env) if name not in _LAYOUT_TASKS else factory(env, int(layout_seed or 0))
    except EnvNotSupported as exc:
        ours = tasks_for(env)
        theirs = f"; {env}'s tasks: {', '.join(ours)}" if ours else ""
        raise ValueError(f"task {name!r} is not defined for env {env!r} (only for {exc}){theirs}") from None


def tasks_for(env: str) -> tuple[str, ...]:
    """The registered tasks defined for `env` (their factories do not refuse it)."""
    found = []
    for name, factory in _FACTORIES.items():
        try:
            factory(env, 0) if name in _LAYOUT_TASKS else factory(env)
        except Exception:  # refused, or a user's factory that fails anyway: not one to offer
            continue
        found.append(name)
    return tuple(found)
