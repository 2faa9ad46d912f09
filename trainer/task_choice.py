"""Which rule a run follows: a built-in task by name (`--task`), a task file (`--task-file`), or none
at all (`--instruction`: people label by their own intent). The chosen definition is written to
OUT/task.json, so a resumed run keeps its rule even when the file was edited since; a run on the
service follows the definition the service holds.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from collie.task_schemas import TaskDefinition
from collie.tasks import NotDeclarative, Task, from_definition, get_task, to_definition
from collie.tasks.task_file import load_task_file
from trainer.config import Config
from trainer.run_files import read_json_object

INSTRUCTION_TASK = "instruction"  # the run's task name when it has no rule
TASK_JSON = "task.json"


@dataclass(frozen=True)
class RunRule:
    """The rule of a run (task and its definition), or only an instruction (task None)."""

    task: Task | None
    definition: TaskDefinition | None  # None: no rule, or a rule function that cannot travel
    instruction: str | None = None

    def to_json(self) -> dict:
        return {
            "definition": None if self.definition is None else self.definition.to_json(),
            "instruction": self.instruction,
        }


def choose_rule(cfg: Config) -> RunRule:
    """The rule `cfg` names (built-in task, task file) or the instruction alone."""
    if cfg.instruction:
        return RunRule(None, None, cfg.instruction)
    if cfg.task_file:
        name = None if cfg.task in ("", INSTRUCTION_TASK) else cfg.task
        return from_stored(load_task_file(cfg.task_file, name, cfg.env, layout_seed=cfg.seed))
    task = get_task(cfg.task, cfg.env, layout_seed=cfg.seed)  # fails early with the list of task names
    try:
        return RunRule(task, to_definition(task, source="builtin"))
    except NotDeclarative:  # a rule function registered in this process: usable offline only
        return RunRule(task, None)


def from_stored(definition: TaskDefinition | None, instruction: str | None = None) -> RunRule:
    """The rule as the service (or OUT/task.json) holds it."""
    return RunRule(None if definition is None else from_definition(definition), definition, instruction)


def saved_rule(out: str | Path) -> RunRule | None:
    """The rule a run folder's earlier process followed (None when it wrote none)."""
    path = Path(out) / TASK_JSON
    if not path.exists():
        return None
    saved = read_json_object(path)  # a damaged one: RunFolderError naming it
    try:
        definition = saved.get("definition")
        if definition is None and saved.get("instruction") is None:
            return None  # a rule function (nothing written down): chosen again from the config
        return from_stored(
            None if definition is None else TaskDefinition.model_validate(definition), saved["instruction"]
        )
    except (ValueError, KeyError) as exc:  # pydantic's errors are ValueErrors
        first = str(exc).splitlines()[0]
        raise ValueError(f"{path} (the run's rule) is damaged: {type(exc).__name__}: {first}") from None


def judged_by(out: str | Path, env: str, task: str, seed: int) -> Task | None:
    """The rule a finished run was judged by: its own saved rule (a task file's; None for an
    instruction alone), else the built-in task of its config."""
    saved = saved_rule(out)
    return saved.task if saved is not None else get_task(task, env, layout_seed=seed)
