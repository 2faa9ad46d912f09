"""The run page's layout in Debian's Chromium against a live service: the labeling card holds its
table at a desktop width, and the whole page fits a phone's width."""

from __future__ import annotations

from typing import Any

import pytest
from service.conftest import TOKENS, make_run_spec, make_session

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MetricsIn, Rollout, RolloutsIn, RunRead

from .conftest import operator_page

WAIT_MS = 30_000


@pytest.fixture(scope="module")
def run(live: BackgroundServer, trainer: CollieClient, operator: CollieClient) -> RunRead:
    """Two labelers, one with a long name; a disagreement; curves and trajectories."""
    created = trainer.create_run(make_run_spec())
    trainer.post_session(created.id, make_session(0, 8))
    for name, values in (("annotator-from-the-night-shift", [0, 1, 2, 0]), ("bo", [1, 1, 2, 2])):
        with CollieClient(live.url, operator.create_labeler(name).token) as client:
            for value in values:
                claim = client.claim(created.id)
                assert claim is not None
                client.submit(created.id, claim.query.query_id, value)  # type: ignore[arg-type]
    trainer.post_metrics(created.id, MetricsIn(epoch=2, values={"safe_ratio": 0.5, "phi_loss": 1.0, "n_labels": 8.0}))
    trainer.post_rollouts(created.id, RolloutsIn(epoch=2, rollouts=[Rollout(skill=[1.0, 0.0], xy=[[0, 0], [1, 1]])]))
    return created


@pytest.fixture(scope="module")
def url(live: BackgroundServer, run: RunRead) -> str:
    return f"{live.url}/?token={TOKENS['operator']}#run={run.id}"


def inside(page: Any, selector: str, card: str) -> list[str]:
    """The elements matching `selector` whose right edge passes the card's content box (what is clipped)."""
    return page.evaluate(
        """([selector, card]) => {
          const box = document.querySelector(card);
          const right = box.getBoundingClientRect().right - parseFloat(getComputedStyle(box).paddingRight);
          return [...box.querySelectorAll(selector)].filter((e) => e.getBoundingClientRect().right > right + 0.5)
            .map((e) => e.textContent);
        }""",
        [selector, card],
    )


@pytest.mark.parametrize("width", [1400, 1024])  # 1024: was cut off at "Di…", reached only by scrolling the card
def test_the_discard_buttons_stay_inside_the_labeling_card(browser: Any, url: str, width: int) -> None:
    with operator_page(browser, url, wait_ms=WAIT_MS) as page:
        page.set_viewport_size({"width": width, "height": 700})
        page.wait_for_selector("#labelers-stats tbody tr button")
        assert inside(page, "#labelers-stats button", "#labeling") == []
        page.click('#labelers-stats tr[data-labeler="annotator-from-the-night-shift"] button')  # armed: longer
        page.wait_for_function("document.querySelector('#labelers-stats button')?.textContent.startsWith('Confirm')")
        assert inside(page, "#labelers-stats button", "#labeling") == []
        assert page.evaluate("(e => e.scrollWidth <= e.clientWidth)(document.querySelector('#labeling'))")


def test_the_page_fits_a_phone_width(browser: Any, url: str, artifacts: Any) -> None:
    """390 × 844: no sideways scroll of the page (wide tables scroll in their own box), and the header
    bar spans the width."""
    context = browser.new_context(bypass_csp=True, viewport={"width": 390, "height": 844}, is_mobile=True)
    try:
        page = context.new_page()
        page.set_default_timeout(WAIT_MS)
        page.goto(url)
        page.wait_for_selector("#labelers-stats tbody tr button")
        page.wait_for_function("document.querySelector('#curves').dataset.points === '1'")
        page.wait_for_function("document.querySelector('#map').dataset.trajectories === '1'")
        widths = page.evaluate(
            "({ page: document.documentElement.scrollWidth, view: document.documentElement.clientWidth,"
            " header: document.querySelector('header').getBoundingClientRect().width })"
        )
        assert widths["view"] == 390
        assert widths["page"] <= widths["view"], f"the page lays out {widths['page']} px wide"
        assert widths["header"] == widths["view"]
        for table in ("#runs table", "#labelers table", "#labelers-stats", "#disagreements table"):
            box = page.locator(table).bounding_box()
            assert box is not None and box["x"] >= 0  # in the page, scrolled (if at all) by its own box
        page.screenshot(path=str(artifacts / "dashboard-phone.png"), full_page=True)
        # Plotly's toolbar sat on the curves' first title (and the map's legend): none at this width
        assert page.locator("#curves .modebar-container .modebar").count() == 0
        assert page.locator("#map .modebar-container .modebar").count() == 0
        title, legend = page.locator("#map .xtitle").bounding_box(), page.locator("#map .legend").bounding_box()
        assert title is not None and legend is not None
        assert title["y"] + title["height"] <= legend["y"]  # the map's x title clear of its wrapped legend
    finally:
        context.close()
