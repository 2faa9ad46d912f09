"""The dashboard in Debian's Chromium draws each run from the rule the service stores with it: a
polygon from a task definition, and for a run with only an instruction the instruction itself, no
regions, and only rule-free curves."""

from __future__ import annotations

from typing import Any

import pytest
from service.conftest import TOKENS, make_run_spec

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MetricsIn
from collie.task_schemas import TaskDefinition

WAIT_MS = 30_000
WEDGE = [[0.0, 0.0], [40.0, -40.0], [40.0, 40.0]]


def open_run(browser: Any, live: BackgroundServer, run_id: int, width: int = 1400) -> Any:
    page = browser.new_page(viewport={"width": width, "height": 1000})
    page.set_default_timeout(WAIT_MS)
    page.goto(f"{live.url}/?token={TOKENS['operator']}#run={run_id}")
    # under the dashboard's content security policy (no bypass_csp): Playwright polls a predicate
    # given as an expression with eval, which the policy refuses; a function ("() => …") it does not
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
    page.wait_for_function("() => (document.querySelector('#map').layout?.shapes ?? []).length === 2")
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
    page.wait_for_function("() => document.querySelector('#curves').dataset.points === '1'")
    assert instruction in page.locator("#run-rule").inner_text()
    titles = page.evaluate("document.querySelector('#curves').layout.annotations.map((a) => a.text)")
    joined = " ".join(titles)
    assert "state coverage" in joined and "labels per class" in joined and "guidance w(s)" in joined
    assert "safe coverage" not in joined and "safe ratio" not in joined
    shapes = page.evaluate("document.querySelector('#map').layout.shapes ?? []")
    assert shapes == []  # nothing pretends to know what is safe
    assert "no task rule" in page.locator("#labeling-body").inner_text()
    page.close()


@pytest.mark.parametrize("viewport", [820, 390])  # 390: a phone, one panel a row (two ran together there)
def test_curve_titles_and_legends_do_not_overlap_on_a_narrow_screen(
    live: BackgroundServer, browser: Any, trainer: CollieClient, artifacts: Any, viewport: int
) -> None:
    run = trainer.create_run(make_run_spec())
    names = ["safe_coverage", "safe_ratio", "composite_coverage", "weighted_composite_coverage", "lambda", "alpha"]
    names += ["phi_loss", "qf_loss", "policy_loss", "n_labels", "n_bins", "n_labels_bad", "n_labels_neutral"]
    names += ["n_labels_good", "w_mean", "w_min", "w_max"]
    for epoch in (1, 2):
        trainer.post_metrics(run.id, MetricsIn(epoch=epoch, values=dict.fromkeys(names, float(epoch))))
    page = open_run(browser, live, run.id, width=viewport)
    page.wait_for_function("() => document.querySelector('#curves').dataset.points === '2'")
    boxes = page.eval_on_selector_all(
        "#curves g.annotation",
        "gs => gs.map(g => { const r = g.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; })",
    )
    page.locator("#curves").screenshot(path=str(artifacts / f"curves-{viewport}px.png"))
    dashes = page.evaluate("Object.fromEntries(document.querySelector('#curves').data.map(t => [t.name, t.line.dash]))")
    classes = [dashes[f"n_labels_{c}"] for c in ("bad", "neutral", "good")]
    assert classes == ["solid", "dash", "dot"]  # was one style: equal counts drew one line over another
    width = page.evaluate("document.querySelector('#curves').getBoundingClientRect().right")
    assert len(boxes) >= 10
    for i, (l1, t1, r1, b1) in enumerate(boxes):
        assert r1 <= width + 1, f"annotation {i} runs off the plot"
        for l2, t2, r2, b2 in boxes[i + 1 :]:
            assert r1 <= l2 or r2 <= l1 or b1 <= t2 or b2 <= t1, "two panels' titles overlap"
    page.close()


def test_the_north_wedge_covers_a_small_view_far_from_its_apex(browser: Any, live: BackgroundServer) -> None:
    """A segment's path picture (Disagreements) is a box a few units wide: at y ≈ 40 the wedge must
    still be drawn there, not stop near y ≈ the box's width."""
    page = browser.new_page()
    page.set_default_timeout(WAIT_MS)
    page.goto(f"{live.url}/?token={TOKENS['operator']}")
    path = page.evaluate(
        """async () => (await import('/js/regions.js')).regionPath(
            {kind: 'wedge_north', apex: [0, 0], desirability: 1}, {x0: 12, x1: 20, y0: 38, y1: 50}, false)"""
    )
    ys = [float(pair.split(",")[1]) for pair in path.strip("MZ").split("L")]  # "Mx,yLx,yLx,yZ"
    assert max(ys) >= 50, path  # the whole box lies inside the triangle drawn
    page.close()
