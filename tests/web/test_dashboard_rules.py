"""The dashboard in Debian's Chromium draws each run from the rule the service stores with it: a
polygon from a task definition, and for a run with only an instruction the instruction itself, no
regions, and only rule-free curves."""

from __future__ import annotations

from typing import Any

from service.conftest import TOKENS, make_run_spec

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MetricsIn
from collie.task_schemas import TaskDefinition

WAIT_MS = 30_000
WEDGE = [[0.0, 0.0], [40.0, -40.0], [40.0, 40.0]]


def open_run(browser: Any, live: BackgroundServer, run_id: int) -> Any:
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.set_default_timeout(WAIT_MS)
    page.goto(f"{live.url}/?token={TOKENS['operator']}#run={run_id}")
    # a selector, not wait_for_function: Playwright evaluates a string predicate with eval when it
    # polls, which the dashboard's content security policy refuses (a failure only when it polls)
    page.wait_for_selector('#curves[data-rendered-at]:not([data-rendered-at=""])', state="attached")
    return page


def test_a_polygon_rule_is_drawn_from_the_stored_definition(
    live: BackgroundServer, browser: Any, trainer: CollieClient
) -> None:
    definition = TaskDefinition.model_validate(
        {"name": "wedge", "description": "Keep out of the east wedge.",
         "regions": [{"kind": "polygon", "desirability": "bad", "vertices": WEDGE}]}
    )  # fmt: skip
    run = trainer.create_run(make_run_spec().model_copy(update={"task": "wedge", "task_definition": definition}))
    trainer.post_metrics(run.id, MetricsIn(epoch=1, values={"safe_coverage": 3.0, "n_bins": 4.0}))
    page = open_run(browser, live, run.id)
    page.wait_for_function("(document.querySelector('#map').layout?.shapes ?? []).length === 2")
    paths = page.evaluate("document.querySelector('#map').layout.shapes.map((s) => s.path ?? null)")
    assert paths[1].startswith("M0.0000,0.0000L40.0000,-40.0000L40.0000,40.0000Z")
    assert page.locator("#run-rule").inner_text() == "Keep out of the east wedge."
    page.close()


def test_an_instruction_run_shows_the_instruction_no_regions_and_only_rule_free_curves(
    live: BackgroundServer, browser: Any, trainer: CollieClient
) -> None:
    instruction = "Keep the robot away from the east side"
    spec = make_run_spec().model_copy(update={"task": "instruction", "instruction": instruction})
    run = trainer.create_run(spec)
    assert run.task_definition is None and run.instruction == instruction
    values = {"n_bins": 12.0, "n_labels": 2.0, "n_labels_bad": 1.0, "n_labels_neutral": 1.0, "w_mean": 0.8}
    trainer.post_metrics(run.id, MetricsIn(epoch=1, values=values))
    page = open_run(browser, live, run.id)
    page.wait_for_function("document.querySelector('#curves').dataset.points === '1'")
    assert instruction in page.locator("#run-rule").inner_text()
    titles = page.evaluate("document.querySelector('#curves').layout.annotations.map((a) => a.text)")
    joined = " ".join(titles)
    assert "state coverage" in joined and "labels per class" in joined and "guidance w(s)" in joined
    assert "safe coverage" not in joined and "safe ratio" not in joined
    shapes = page.evaluate("document.querySelector('#map').layout.shapes ?? []")
    assert shapes == []  # nothing pretends to know what is safe
    assert "no task rule" in page.locator("#labeling-body").inner_text()
    page.close()
