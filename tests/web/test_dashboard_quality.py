"""The dashboard for the people who run labeling, in Debian's Chromium against a live service:
labeler management (create → a one-time token and a labeler link, list, revoke), the labeling
panel's counts (revisions are no labels), agreement and explanations, the list of disagreements
with their paths and replay links, the run's quality settings, and the legends of the charts."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
from service.conftest import DIMS, TOKENS, make_run_spec, make_session

from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import MetricsIn, Rollout, RolloutsIn, RunRead

from .conftest import operator_page

WAIT_MS = 30_000
UI = "http://labeling.example:8080/"


@pytest.fixture(scope="module")
def run(live: BackgroundServer, trainer: CollieClient, operator: CollieClient) -> RunRead:
    """A range_north run with redundancy 2, labelled by two labelers who disagree on 0-1 (and the oracle
    on 0-2), with a revision; metrics and rollouts for the charts."""
    created = trainer.create_run(make_run_spec(task="range_north").model_copy(update={"redundancy": 2}))
    post = make_session(0, 3)
    for q, y in zip(post.queries, [-3.0, -3.0, -30.0], strict=True):  # oracle: neutral, neutral, bad
        q.xy = [[0.5, y + 0.05 * i] for i in range(DIMS.horizon)]
    trainer.post_session(created.id, post)
    plan = {"web-a": {"0-0": 1, "0-1": 1, "0-2": 2}, "web-b": {"0-0": 1, "0-1": 0, "0-2": 2}}
    for name, answers in plan.items():
        with CollieClient(live.url, operator.create_labeler(name).token) as client:
            for _ in range(3):
                claim = client.claim(created.id)
                client.submit(created.id, claim.query.query_id, answers[claim.query.query_id])  # type: ignore[arg-type]
            if name == "web-a":
                client.submit(created.id, "0-0", 2)  # two revisions: still one label of web-a's
                client.submit(created.id, "0-0", 1)
    for epoch in (2, 4):
        values = {"safe_ratio": 0.5, "phi_loss": 1.0 / epoch, "qf_loss": 2.0 / epoch, "n_labels": 3.0}
        values |= {"n_labels_bad": 1.0, "n_labels_neutral": 1.0, "n_labels_good": 1.0}
        trainer.post_metrics(created.id, MetricsIn(epoch=epoch, values=values))
    trainer.post_rollouts(created.id, RolloutsIn(epoch=4, rollouts=[Rollout(skill=[1.0, 0.0], xy=[[0, 0], [1, 1]])]))
    return created


@pytest.fixture(scope="module")
def page(live: BackgroundServer, browser: Any, run: RunRead) -> Iterator[Any]:
    url = f"{live.url}/?token={TOKENS['operator']}&ui={UI}#run={run.id}"
    with operator_page(browser, url, clipboard=True, wait_ms=WAIT_MS) as page:
        page.wait_for_selector("#labelers-stats")
        yield page


def clipboard(page: Any, expected: str, timeout_s: float = 10.0) -> str:
    """The clipboard's text once it is `expected` or `timeout_s` passed: the page writes it after
    the click has returned."""
    deadline = time.monotonic() + timeout_s
    while (text := page.evaluate("navigator.clipboard.readText()")) != expected and time.monotonic() < deadline:
        time.sleep(0.05)
    return text


def test_an_operator_creates_lists_and_revokes_a_labeler(page: Any, live: BackgroundServer) -> None:
    page.fill("#labeler-name", "alice-web")
    page.click("#labeler-create")
    page.wait_for_selector("#labeler-created:not([hidden])")
    token = page.input_value("#created-token")
    assert page.input_value("#created-link") == f"{UI}?token={token}"
    page.click("#copy-link")
    assert clipboard(page, f"{UI}?token={token}") == f"{UI}?token={token}"
    with CollieClient(live.url, token) as alice:
        assert alice.me().name == "alice-web"  # a real token of a labeler
        page.wait_for_selector('#labelers-body tr[data-labeler="alice-web"]')
        page.fill("#labeler-name", "alice-web")
        page.click("#labeler-create")
        page.wait_for_function("document.querySelector('#labeler-message').textContent.includes('taken')")
        assert page.is_hidden("#labeler-created")  # alice's token box is not this attempt's
        bad_names = [("José 🚀", "may hold only A–Z"), ("  ", "give the labeler a name"), ("x" * 65, "at most 64")]
        for name, said in bad_names:
            page.fill("#labeler-name", name)
            page.click("#labeler-create")
            page.wait_for_function(f"document.querySelector('#labeler-message').textContent.includes({said!r})")
        page.fill("#labeler-name", "bob-web")
        assert page.text_content("#labeler-message") == ""  # typing again clears the old error
        page.click("#labeler-create")
        page.wait_for_selector('#labelers-body tr[data-labeler="bob-web"]')
        button = page.locator('#labelers-body tr[data-labeler="alice-web"] button')
        other = page.locator('#labelers-body tr[data-labeler="bob-web"] button')
        other.click()
        button.click()
        assert button.text_content() == "Confirm revoke"  # one click only arms it
        assert other.text_content() == "Revoke"  # and disarms the other
        alice.me()
        button.click()
        page.wait_for_selector('#labelers-body tr.revoked[data-labeler="alice-web"]')
        assert page.is_hidden("#labeler-created")
        with pytest.raises(ApiError) as refused:
            alice.me()
        assert refused.value.status == 401


def test_the_panel_counts_labels_not_revisions_and_explains_each_metric(page: Any) -> None:
    counts = page.eval_on_selector_all(
        "#labelers-stats tbody tr", "rows => rows.map(r => [r.dataset.labeler, r.querySelector('.labels').textContent])"
    )
    assert counts == [["web-a", "3"], ["web-b", "3"]]  # web-a sent 5 label events
    assert page.text_content("#m-quality").startswith("2 labels per query from distinct labelers")
    # units {1,1}, {1,0}, {2,2}: n = 6, n_0 = 1, n_1 = 3, n_2 = 2; α = 1 − 5 · 2 / (36 − 14) = 6/11
    assert page.text_content("#m-alpha").startswith("α = 0.55 on 3 queries")
    explained = page.eval_on_selector_all("#labeling-body dd", "dds => dds.map(d => !!d.querySelector('.explain'))")
    assert explained and all(explained)  # every metric has its line
    help_terms = page.eval_on_selector_all("#labeling-body .explain-list b", "bs => bs.map(b => b.textContent)")
    assert help_terms == ["labels", "skips", "median", "oracle agrees", "α", "gold", "discard labels"]


def test_disagreements_are_listed_with_their_paths(page: Any) -> None:
    rows = page.eval_on_selector_all("#disagreements-body tr[data-query]", "rows => rows.map(r => r.dataset.query)")
    assert rows == ["0-2", "0-1"]  # 0-2: both said good, the rule says bad; 0-1: neutral vs bad
    row = page.locator('#disagreements-body tr[data-query="0-1"]')
    assert "web-a neutral" in row.text_content() and "web-b bad" in row.text_content()
    points = row.locator("svg.path-view polyline").get_attribute("points")
    assert len(points.split()) == DIMS.horizon
    assert row.locator("svg.path-view path").count() >= 1  # the task's regions under the path
    assert "(2)" in page.text_content("#disagreements-count")


def test_each_disagreement_links_to_its_replay_in_3d(page: Any, run: RunRead) -> None:
    """The labeling UI's review mode (tests/ui/test_review.py follows the link), signed in with
    this page's token in the tab it opens only."""
    link = page.locator('#disagreements-body tr[data-query="0-1"] a.replay-3d')
    assert link.text_content() == "replay in 3D" and link.get_attribute("target") == "_blank"
    assert link.get_attribute("href") == f"{UI}?review={run.id}&query=0-1&token={TOKENS['operator']}"
    assert page.locator("#disagreements-body a.replay-3d").count() == 2  # one per listed query


def test_the_quality_settings_are_set_from_the_panel(page: Any, trainer: CollieClient, run: RunRead) -> None:
    assert page.input_value("#quality-redundancy") == "2"
    page.fill("#quality-redundancy", "3")
    page.fill("#quality-gold", "10")
    page.click("#quality-apply")
    page.wait_for_function("document.querySelector('#quality').dataset.redundancy === '3'")
    changed = trainer.run(run.id)
    assert (changed.redundancy, changed.gold_rate) == (3, 0.1)
    page.wait_for_function("document.querySelector('#quality-message').textContent === 'applied'")
    for value, said in (("0", "redundancy: a whole number"), ("", "redundancy: a whole number")):
        page.fill("#quality-redundancy", value)
        page.click("#quality-apply")
        page.wait_for_function(f"document.querySelector('#quality-message').textContent.startsWith({said!r})")
    page.fill("#quality-redundancy", "3")
    page.fill("#quality-gold", "60")  # a percentage: refused before it is sent as 0.6
    page.click("#quality-apply")
    page.wait_for_function("document.querySelector('#quality-message').textContent.startsWith('gold: a whole')")
    assert (trainer.run(run.id).redundancy, trainer.run(run.id).gold_rate) == (3, 0.1)


def test_apply_sends_only_what_was_typed(
    page: Any, trainer: CollieClient, operator: CollieClient, run: RunRead
) -> None:
    """Another operator set r = 4 meanwhile: this panel follows it, and its gold change keeps it."""
    page.reload()  # the test before left typed, unapplied values
    page.wait_for_function("document.querySelector('#quality-redundancy').value === '3'")
    operator.set_quality(run.id, redundancy=4)
    page.wait_for_function("document.querySelector('#quality-redundancy').value === '4'", timeout=30_000)
    page.fill("#quality-gold", "20")
    page.click("#quality-apply")
    page.wait_for_function("document.querySelector('#quality-message').textContent === 'applied'")
    assert (trainer.run(run.id).redundancy, trainer.run(run.id).gold_rate) == (4, 0.2)


def test_the_charts_have_legends_and_labelled_states_are_large(page: Any, artifacts: Any) -> None:
    page.wait_for_function("document.querySelector('#curves').dataset.points === '2'")
    titles = page.eval_on_selector_all("#curves .annotation-text", "ts => ts.map(t => t.textContent)")
    losses = next(t for t in titles if t.startswith("losses"))
    assert "phi_loss" in losses and "qf_loss" in losses
    helped = page.eval_on_selector_all("#curves-help li b", "bs => bs.map(b => b.textContent)")
    assert "losses" in helped and "safe ratio" in helped
    lines = page.evaluate("Object.fromEntries(document.querySelector('#curves').data.map(t => [t.name, t.line.color]))")
    markers_by_class = page.evaluate(
        "Object.fromEntries(document.querySelector('#map').data.filter(t => t.name.startsWith('labelled'))"
        ".map(t => [t.name.split(' ')[1], t.marker.color]))"
    )
    # the labels-per-class curves wear the map's class colours: one colour means one class on the page
    assert {c: lines[f"n_labels_{c}"] for c in ("bad", "neutral", "good")} == markers_by_class
    page.wait_for_function("document.querySelector('#map').dataset.labelled === '3'")
    legend = page.eval_on_selector_all("#map .legendtext", "ts => ts.map(t => t.textContent)")
    assert any(t.startswith("evaluation trajectories") for t in legend)
    assert {"bad region", "neutral region"} <= set(legend)
    markers = page.evaluate(
        "document.querySelector('#map').data.filter(t => t.name.startsWith('labelled'))"
        ".map(t => [t.marker.size, t.marker.symbol])"
    )
    assert all(max(sizes) >= 10 for sizes, _ in markers)  # each segment ends in a large marker of its class's shape
    assert len({symbol for _, symbol in markers}) == 3  # bad, neutral, good: three shapes
    page.screenshot(path=str(artifacts / "dashboard-quality.png"), full_page=True)


def test_the_labeler_table_stays_inside_its_card(page: Any) -> None:
    page.set_viewport_size({"width": 1400, "height": 900})
    page.wait_for_selector("#labelers-stats tbody tr button")
    card = page.locator("#labeling").bounding_box()
    button = page.locator("#labelers-stats tbody tr button").first.bounding_box()
    assert card is not None and button is not None
    visible_right = card["x"] + card["width"]
    assert button["x"] + button["width"] <= visible_right  # inside the card (test_dashboard_layout.py: armed too)
    no_page_scroll = "document.documentElement.scrollWidth <= document.documentElement.clientWidth"
    assert page.evaluate(no_page_scroll)
