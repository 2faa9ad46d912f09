"""Tasks from files (--task-file) and the wire form of a rule: a spec file becomes the same Task
every process rebuilds from the definition the service holds; every bad file fails with an error
naming the file, the line or key, and what was expected."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from collie.schemas import EnvDims, RunCreate
from collie.task_schemas import TaskDefinition
from collie.tasks import (
    BAD,
    GOOD,
    NEUTRAL,
    NotDeclarative,
    Polygon,
    Task,
    from_definition,
    get_task,
    task_names,
    to_definition,
)
from collie.tasks import registry as task_registry
from collie.tasks.task_file import TaskFileError, load_task_file

POLYGON_TOML = """\
name = "pit_test"
description = "Keep out of the L-shaped pit."
background = "neutral"

[meaning]
bad = "inside the pit"
neutral = "anywhere else"

[[regions]]
kind = "polygon"
name = "pit"
desirability = "bad"
vertices = [[0, 0], [4, 0], [4, 1], [1, 1], [1, 4], [0, 4]]

[[regions]]
kind = "disc"
desirability = "good"
centre = [10, 10]
radius = 2
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_polygon_is_the_even_odd_interior_with_the_edge_convention() -> None:
    ell = [(0, 0), (4, 0), (4, 1), (1, 1), (1, 4), (0, 4)]  # concave: the notch (2, 2) is outside
    bad = Task("ell", "", regions=(Polygon(ell, desirability=BAD),))
    good = Task("ell", "", regions=(Polygon(ell, desirability=GOOD),))
    points = np.array([[0.5, 0.5], [3.5, 0.5], [0.5, 3.5], [2.0, 2.0], [5.0, 0.5], [4.0, 0.5], [-1.0, -1.0]])
    assert bad.classify(points).tolist() == [BAD, BAD, BAD, NEUTRAL, NEUTRAL, NEUTRAL, NEUTRAL]  # edge is safe
    assert good.classify(points).tolist()[5] == GOOD  # a region not painted bad owns its edge
    assert np.allclose(bad.boundary_distance(points), [0.5, 0.5, 0.5, 1.0, 1.0, 0.0, np.sqrt(2)])
    with pytest.raises(ValueError, match="no area"):
        Polygon([(0, 0), (1, 1), (2, 2)], desirability=BAD)


def test_every_builtin_task_survives_its_wire_form() -> None:
    rng = np.random.default_rng(0)
    xy, pitch = rng.uniform(-30, 30, (3000, 2)), rng.uniform(-4, 4, 3000)
    checked = set()
    for name in task_names():
        for env in ("point", "quadruped", "car"):
            try:
                task = get_task(name, env, layout_seed=5)
            except ValueError:
                continue  # not defined for this env
            wire = TaskDefinition.model_validate(json.loads(json.dumps(to_definition(task).to_json())))
            again = from_definition(wire)
            assert again.to_dict() == task.to_dict(), (name, env)
            assert (again.classify(xy, pitch) == task.classify(xy, pitch)).all(), (name, env)
            assert np.allclose(again.boundary_distance(xy, pitch), task.boundary_distance(xy, pitch))
            checked.add(name)
    assert checked == set(task_names())  # every task is defined for one of these envs at least


def test_a_rule_function_cannot_travel() -> None:
    with pytest.raises(NotDeclarative, match="rule function"):
        to_definition(Task("f", "", rule=lambda xy, pitch: np.zeros(len(xy), int)))


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_a_spec_file_gives_the_definition_it_writes(tmp_path: Path, suffix: str) -> None:
    import tomllib

    data = tomllib.loads(POLYGON_TOML)
    text = POLYGON_TOML if suffix == ".toml" else json.dumps(data, indent=1)
    definition = load_task_file(write(tmp_path, "pit" + suffix, text))
    assert definition.name == "pit_test" and definition.source == "pit" + suffix
    task = from_definition(definition)
    assert task.meaning[BAD] == "inside the pit" and task.can_be_good
    assert task.classify(np.array([[0.5, 2.0], [2.0, 2.0], [10.0, 11.0]])).tolist() == [BAD, NEUTRAL, GOOD]
    assert task.to_dict()["regions"][0] == {
        "kind": "polygon",
        "desirability": BAD,
        "vertices": data["regions"][0]["vertices"],
    }


def test_the_file_stem_names_an_unnamed_task(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "east side.json",
        '{"description": "d", "regions": [{"kind": "halfplane_right", "desirability": 0, "x0": 3}]}',
    )
    definition = load_task_file(path)
    assert definition.name == "east_side"
    assert from_definition(definition).classify(np.array([[2.0, 0.0], [4.0, 0.0]])).tolist() == [NEUTRAL, BAD]


BAD_SPECS = [
    # (file text, the key or line the error must name, what it must say was expected)
    ('description = "d"\n[[regions]]\nkind = "circle"\ndesirability = 0\n', "regions[0].kind", "expected one of disc"),
    (
        'description = "d"\n[[regions]]\nkind = "disc"\ndesirability = 0\ncentre = [0, 0]\n',
        "regions[0].radius",
        "Field required",
    ),
    ('[[regions]]\nkind = "disc"\ndesirability = 0\ncentre = [0, 0]\nradius = 1\n', "description", "Field required"),
    ('description = "d"\n', "regions", "Field required"),
    (
        'description = "d"\n[[regions]]\nkind = "disc"\ndesirability = "awful"\ncentre = [0, 0]\nradius = 1\n',
        "regions[0].desirability",
        "'bad', 'neutral' or 'good'",
    ),
    (
        'description = "d"\n[[regions]]\nkind = "disc"\ndesirability = 0\ncentre = [0, 0]\nradius = -1\n',
        "regions[0].radius",
        "greater than 0",
    ),
    (
        'description = "d"\n[[regions]]\nkind = "disc"\ndesirability = 0\ncentre = [0, 0]\nradius = 1\nradious = 2\n',
        "regions[0].radious",
        "Extra inputs",
    ),
    (
        'description = "d"\n[[regions]]\nkind = "polygon"\ndesirability = 0\nvertices = [[0, 0], [1, 1]]\n',
        "regions[0].vertices",
        "at least 3",
    ),
    (
        'description = "d"\n[[regions]]\nkind = "polygon"\ndesirability = 0\nvertices = [[0, 0], [1, 1], [2, 2]]\n',
        "regions[0].vertices",
        "no area",
    ),
    (
        'description = "d"\n[[regions]]\nkind = "disc"\nname = "pond"\ndesirability = 0\ncentre = [0, 0]\nradius = 1\n'
        '[[regions]]\nkind = "disc"\nname = "pond"\ndesirability = 0\ncentre = [5, 0]\nradius = 1\n',
        "regions[1] and regions[0] are both named 'pond'",
        "",
    ),
    (  # past MAX_COORDINATE a rule's squares overflow float64: NaN verdicts (was accepted)
        'description = "d"\n[[regions]]\nkind = "disc"\ndesirability = 0\ncentre = [1.7e308, 0]\nradius = 1\n',
        "regions[0].centre[0]",
        "less than or equal to 1000000",
    ),
    (
        'description = "d"\n[[regions]]\nkind = "disc"\ndesirability = 0\ncentre = [0, 0]\nradius = 1e300\n',
        "regions[0].radius",
        "less than or equal to 1000000",
    ),
    ('name = "north"\ndescription = "d"\nregions = []\n', "name", "already a registered task"),
    ('description = "d"\nregions = 5\n', "regions", "valid list (got 5)"),  # was a TypeError traceback
    ('description = "d"\nregions = true\n', "regions", "valid list (got True)"),
    ('description = "d"\nregions = [\n  { kind = "disc" \n', "line 3", "not valid TOML"),
]


@pytest.mark.parametrize(("text", "where", "expected"), BAD_SPECS)
def test_a_bad_spec_file_names_the_file_the_key_and_what_was_expected(
    tmp_path: Path, text: str, where: str, expected: str
) -> None:
    path = write(tmp_path, "bad.toml", text)
    with pytest.raises(TaskFileError) as caught:
        load_task_file(path)
    message = str(caught.value)
    assert str(path) in message and where in message and expected in message, message
    # pydantic's framing stays out: no "Value error," prefix, no whole file as the value given, one "got"
    assert "Value error" not in message and "(top level)" not in message and message.count("got ") <= 1, message


def test_bad_json_names_its_line(tmp_path: Path) -> None:
    path = write(tmp_path, "bad.json", '{\n  "description": "d",\n  "regions": [,]\n}\n')
    with pytest.raises(TaskFileError, match=r"bad.json: line 3, column \d+: not valid JSON"):
        load_task_file(path)


def test_other_files_are_refused_clearly(tmp_path: Path) -> None:
    with pytest.raises(TaskFileError, match="no such file"):
        load_task_file(tmp_path / "missing.toml")
    with pytest.raises(TaskFileError, match=r"expected a \.toml, \.json or \.py file"):
        load_task_file(write(tmp_path, "task.yaml", "a: 1"))
    with pytest.raises(TaskFileError, match="expected a table"):
        load_task_file(write(tmp_path, "list.json", "[1, 2]"))
    spec = write(tmp_path, "pit.toml", POLYGON_TOML)
    with pytest.raises(TaskFileError, match="defines task 'pit_test', not 'other'"):
        load_task_file(spec, task="other")


def test_a_python_task_file_registers_tasks_and_yields_their_definition(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "charger.py",
        """\
        from collie.tasks import BAD, GOOD, Disc, OutsideDisc, Task, register_task

        @register_task("charger_test")
        def charger(env):
            return Task("charger_test", "Stay near the charger.", regions=(
                OutsideDisc((0.0, 0.0), 10.0, desirability=BAD), Disc((3.0, 0.0), 1.0, desirability=GOOD)))
        """,
    )
    definition = load_task_file(path, env="ant")
    assert definition.name == "charger_test" and definition.source == "charger.py"
    assert [r.kind for r in definition.regions] == ["outside_disc", "disc"]
    assert from_definition(definition).classify(np.array([[3.0, 0.0], [20.0, 0.0]])).tolist() == [GOOD, BAD]


def test_bad_python_task_files_are_refused_clearly(tmp_path: Path) -> None:
    with pytest.raises(TaskFileError, match=r"broken.py: line 2: not valid Python"):
        load_task_file(write(tmp_path, "broken.py", "x = 1\ndef f(:\n"))
    with pytest.raises(TaskFileError, match="registers no task"):
        load_task_file(write(tmp_path, "empty.py", "x = 1\n"))
    with pytest.raises(TaskFileError, match="'north' is already registered"):
        load_task_file(
            write(tmp_path, "clash.py", "from collie.tasks import register_task\nregister_task('north')(len)\n")
        )
    rule = """\
    import numpy as np
    from collie.tasks import Task, register_task
    register_task("rule_fn_test")(lambda env: Task("rule_fn_test", "d", rule=lambda xy, p: np.ones(len(xy), int)))
    """
    with pytest.raises(TaskFileError, match="rule_fn_test: task 'rule_fn_test' is a rule function"):
        load_task_file(write(tmp_path, "rule.py", rule))
    two = """\
    from collie.tasks import Task, register_task
    register_task("two_a_test")(lambda env: Task("two_a_test", "d"))
    register_task("two_b_test")(lambda env: Task("two_b_test", "d"))
    """
    with pytest.raises(TaskFileError, match="registers two_a_test, two_b_test; pick one with --task"):
        load_task_file(write(tmp_path, "two.py", two))
    with pytest.raises(TaskFileError, match="registers two_c_test, two_d_test, not 'zzz'; pick one of them"):
        load_task_file(write(tmp_path, "two_more.py", two.replace("two_a", "two_c").replace("two_b", "two_d")), "zzz")


def test_a_run_has_a_rule_or_an_instruction_not_both() -> None:
    dims = EnvDims(obs_dim=4, nq=2, nv=2, horizon=5, skill_dim=2)
    definition = to_definition(get_task("north"))
    with pytest.raises(ValidationError, match="not both"):
        RunCreate(env="point", task="x", method="collie", dims=dims, task_definition=definition, instruction="be nice")
    with pytest.raises(ValidationError):
        RunCreate(env="point", task="x", method="collie", dims=dims, instruction="")


def test_the_spec_file_in_the_docs_loads(tmp_path: Path) -> None:
    docs = (Path(__file__).parents[1] / "docs" / "tasks.md").read_text()
    block = docs.split("```toml\n", 1)[1].split("```", 1)[0]
    task = from_definition(load_task_file(write(tmp_path, "charger.toml", block)))
    xy = np.array([[0.0, 0.0], [5.0, 5.0], [6.0, 0.0], [20.0, 0.0]])
    assert task.name == "charger" and task.classify(xy).tolist() == [GOOD, NEUTRAL, BAD, BAD]


def test_a_python_task_file_that_fails_names_the_file_and_line(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(task_registry, "_FACTORIES", dict(task_registry._FACTORIES))  # its failing factory goes
    with pytest.raises(
        TaskFileError, match=r"missing_mod.py: line 2: running it raised ModuleNotFoundError: .*nowhere"
    ):
        load_task_file(write(tmp_path, "missing_mod.py", "x = 1\nimport nowhere_to_be_found\n"))
    with pytest.raises(TaskFileError, match=r"raises.py: line 1: running it raised ZeroDivisionError"):
        load_task_file(write(tmp_path, "raises.py", "1 / 0\n"))
    factory = """\
    from collie.tasks import register_task
    @register_task("factory_fails_test")
    def f(env):
        return {}["oops"]
    """
    with pytest.raises(TaskFileError, match=r"factory.py: line 4: KeyError: 'oops'"):
        load_task_file(write(tmp_path, "factory.py", factory))


def test_a_directory_or_non_utf8_spec_is_named(tmp_path: Path) -> None:
    with pytest.raises(TaskFileError, match="is a directory"):
        load_task_file(tmp_path)
    with pytest.raises(TaskFileError, match="/dev/null: is not a regular file"):  # was: "no such file"
        load_task_file("/dev/null")
    latin = tmp_path / "latin.toml"
    latin.write_bytes('# a comment\nname = "caf\xe9"\n'.encode("latin-1"))
    with pytest.raises(TaskFileError, match=r"latin.toml: line 2: not UTF-8 text"):
        load_task_file(latin)


def test_a_pitch_rule_on_the_point_mass_is_refused(tmp_path: Path) -> None:
    spec = tmp_path / "upright.toml"
    spec.write_text(
        'name = "upright"\ndescription = "stay upright"\n'
        '[[regions]]\nkind = "pitch_beyond"\ndesirability = "bad"\nlimit = 1.0\n'
    )
    assert load_task_file(spec, env="ant").name == "upright"
    with pytest.raises(TaskFileError, match="regions: a pitch_beyond region needs a body that can tip over; point"):
        load_task_file(spec, env="point")
