"""The labeling UI in a real browser shows each run's rule as the service stores it: a polygon from
a task definition (its text, and its edge and tint on the floor), or for a run without a rule the
person's instruction, over no regions at all."""

from __future__ import annotations

import time

import pytest
from playwright.sync_api import Browser

from collie.schemas import RunCreate
from collie.task_schemas import TaskDefinition

from .page import open_labeler, wait_segment, wait_text
from .stack import Stack, dims_of

pytestmark = pytest.mark.slow
WEDGE = [[0.0, 0.0], [40.0, -40.0], [40.0, 40.0]]


def post(stack: Stack, **rule: object) -> int:
    spec = RunCreate(env="point", method="collie", dims=dims_of("point"), n_total=10, **rule)  # type: ignore[arg-type]
    run = stack.trainer.create_run(spec)
    stack.post_session(run.id, "point", 0, 2)
    stack.trainer.set_status(run.id, "waiting_for_labels", epoch=3)
    return run.id


def floor_nodes(app: object, deadline_s: float = 30.0) -> list[str]:
    """Names of the floor's region and tint nodes in the (only) labeler's scene, once it is set."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        sessions = list(app.sessions.values())  # type: ignore[attr-defined]
        if sessions and sessions[0].scene.floor_key is not None:
            return [handle.name.rsplit("/", 1)[-1] for handle in sessions[0].scene._floor]
        time.sleep(0.2)
    raise AssertionError("the floor was never set")


def test_a_polygon_definition_is_what_the_labeler_reads_and_sees(stack: Stack, browser: Browser) -> None:
    definition = TaskDefinition.model_validate(
        {"name": "east_wedge", "description": "Keep out of the wedge east of the start.",
         "meaning": {"bad": "inside the east wedge"},
         "regions": [{"kind": "polygon", "desirability": "bad", "vertices": WEDGE}]}
    )  # fmt: skip
    run_id = post(stack, task="east_wedge", task_definition=definition)
    app = stack.ui(run_id)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("polygon-reader")))
    wait_segment(page)
    wait_text(page, "Keep out of the wedge east of the start.")
    wait_text(page, "inside the east wedge")
    nodes = floor_nodes(app)
    assert "region0" in nodes and any(n.startswith("tint") for n in nodes)  # its edge, and its bad side tinted
    page.context.close()


def test_an_instruction_run_shows_the_instruction_and_no_regions(stack: Stack, browser: Browser) -> None:
    instruction = "Keep the robot away from the east side"
    run_id = post(stack, task="instruction", instruction=instruction)
    app = stack.ui(run_id)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("instruction-reader")))
    wait_segment(page)
    wait_text(page, instruction)
    wait_text(page, "the robot does what the instruction asks for")
    assert floor_nodes(app) == []  # nothing pretends to know what is safe
    page.context.close()
