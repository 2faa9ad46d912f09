"""`--task-file PATH`: a task rule from a file the user wrote (docs/tasks.md), always ending as a
declarative TaskDefinition, which is what travels with the run to the service.

- `.toml` / `.json`: the TaskDefinition itself (a background class and regions); the file's stem
  names the task unless it says `name`.
- `.py`: a Python file that registers tasks with `@register_task`. It runs only here, in the
  process the user started (the trainer), never in the service; the task it builds must be
  painted from regions, since only its definition (not its code) travels: every other process
  judges the run from that stored definition, and editing the file later changes no running run.

Every problem is a TaskFileError naming the file, the line or key, and what was expected.
"""

from __future__ import annotations

import json
import re
import runpy
import tomllib
import traceback
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from collie.task_schemas import REGION_KINDS, TaskDefinition
from collie.tasks.builtin import PITCHLESS_ENVS
from collie.tasks.definition import NotDeclarative, from_definition, to_definition
from collie.tasks.registry import get_task, task_names

SPEC_SUFFIXES = (".toml", ".json")


class TaskFileError(ValueError):
    def __init__(self, path: Path, where: str, what: str) -> None:
        self.path, self.where, self.what = path, where, what
        super().__init__(f"task file {path}: {where}: {what}" if where else f"task file {path}: {what}")


def load_task_file(
    path: str | Path, task: str | None = None, env: str = "point", layout_seed: int = 0
) -> TaskDefinition:
    """The definition in the spec file `path`, or of task `task` (or the only one) that the
    Python file `path` registers, built for `env` and the run's `layout_seed`."""
    path = Path(path)
    if path.is_dir():
        raise TaskFileError(path, "", "is a directory, not a task file")
    if not path.exists():
        raise TaskFileError(path, "", "no such file")
    if not path.is_file():  # /dev/null, a pipe: nothing a rule could be read from
        raise TaskFileError(path, "", "is not a regular file (a task file is a .toml, .json or .py file)")
    if path.suffix == ".py":
        definition = _from_python(path, task, env, layout_seed)
    elif path.suffix not in SPEC_SUFFIXES:
        raise TaskFileError(path, "", f"expected a .toml, .json or .py file, got {path.suffix or 'no suffix'!r}")
    else:
        definition = parse_spec(path, _read_spec(path))
    if task is not None and task != definition.name:
        raise TaskFileError(path, "name", f"the file defines task {definition.name!r}, not {task!r}")
    if env in PITCHLESS_ENVS and any(region.kind == "pitch_beyond" for region in definition.regions):
        raise TaskFileError(path, "regions", f"a pitch_beyond region needs a body that can tip over; {env} has none")
    return definition


def _read_spec(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        line = exc.object[: exc.start].count(b"\n") + 1
        raise TaskFileError(path, f"line {line}", "not UTF-8 text (save it as UTF-8)") from None
    try:
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except tomllib.TOMLDecodeError as exc:  # its message says "(at line L, column C)"
        raise TaskFileError(path, "", f"not valid TOML: {exc}") from None
    except json.JSONDecodeError as exc:
        raise TaskFileError(path, f"line {exc.lineno}, column {exc.colno}", f"not valid JSON: {exc.msg}") from None
    if not isinstance(data, dict):
        raise TaskFileError(path, "", f"expected a table (an object) at the top, got {type(data).__name__}")
    return data


def parse_spec(path: Path, data: dict[str, Any]) -> TaskDefinition:
    data = {"name": _stem_name(path), **data, "source": path.name}
    regions = data.get("regions")  # anything but a list is the schema's to refuse, below
    for i, region in enumerate(regions if isinstance(regions, list) else []):
        kind = region.get("kind") if isinstance(region, dict) else None
        if isinstance(region, dict) and kind is not None and kind not in REGION_KINDS:
            raise TaskFileError(
                path, f"regions[{i}].kind", f"unknown region kind {kind!r}; expected one of {', '.join(REGION_KINDS)}"
            )
    try:
        definition = TaskDefinition.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        msg = first["msg"].removeprefix("Value error, ")  # our validators' own words
        # the value given, unless the words name it already, or it is the whole file (a rule across fields)
        quiet = first["type"] == "missing" or not first["loc"] or "got " in msg
        got = "" if quiet else f" (got {_shown(first.get('input'))})"
        raise TaskFileError(path, _key(first["loc"]), f"{msg}{got}") from None
    if definition.name in task_names():
        raise TaskFileError(path, "name", f"{definition.name!r} is already a registered task; choose another name")
    try:
        from_definition(definition)  # geometry the schema cannot see (e.g. a polygon without area)
    except ValueError as exc:
        raise TaskFileError(path, "regions", str(exc)) from None
    return definition


def _from_python(path: Path, task: str | None, env: str, layout_seed: int) -> TaskDefinition:
    before = set(task_names())
    try:
        runpy.run_path(str(path), run_name=f"collie_task_file_{_stem_name(path)}")
    except SyntaxError as exc:
        raise TaskFileError(path, f"line {exc.lineno}", f"not valid Python: {exc.msg}") from None
    except ValueError as exc:  # e.g. registering a name that is taken
        raise TaskFileError(path, "", str(exc)) from None
    except Exception as exc:  # the user's code failed (a missing module, a bug): say where, not a traceback
        raise TaskFileError(path, _line_in(path, exc), f"running it raised {type(exc).__name__}: {exc}") from None
    added = [n for n in task_names() if n not in before]
    if not added:
        raise TaskFileError(path, "", "registers no task; decorate a factory with @collie.tasks.register_task('name')")
    if task is None or task not in added:
        if task is not None:
            raise TaskFileError(path, "", f"registers {', '.join(added)}, not {task!r}; pick one of them with --task")
        if len(added) > 1:
            raise TaskFileError(path, "", f"registers {', '.join(added)}; pick one with --task")
        task = added[0]
    try:
        return to_definition(get_task(task, env, layout_seed=layout_seed), source=path.name)
    except NotDeclarative as exc:
        raise TaskFileError(path, task, str(exc)) from None
    except Exception as exc:  # its factory is the user's code too
        detail = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
        raise TaskFileError(path, _line_in(path, exc) or task, detail) from None


def _line_in(path: Path, exc: BaseException) -> str:
    """'line N' of the innermost frame of the traceback that ran in `path` ('' if none did)."""
    lines = [f.lineno for f in traceback.extract_tb(exc.__traceback__) if Path(f.filename) == path]
    return f"line {lines[-1]}" if lines else ""


def _stem_name(path: Path) -> str:
    return re.sub(r"[^A-Za-z0-9_.:+-]", "_", path.stem)[:64] or "task"


def _key(loc: tuple[Any, ...]) -> str:
    """('regions', 2, 'polygon', 'vertices') → 'regions[2].vertices' (the union's tag dropped)."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part not in REGION_KINDS:
            out += f".{part}" if out else str(part)
    return out


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
