"""The dashboard shows the newest of what it heard when answers come back out of order, in Debian's
Chromium against a live service: the test holds chosen answers (Playwright's page.route) and lets
them through late, as a busy machine or network does. Each hold makes one interleaving happen every
time; each check waits for a later answer that has to pass through the service, so the late one has
long been handled by then."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, BrowserContext, Page, Route
from service.conftest import TOKENS, make_run_spec, make_session

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.schemas import MetricsIn, Rollout, RolloutsIn

WAIT_MS = 30_000
PLOTLY = "**/vendor/plotly-basic.min.js"  # held: every chart waits for it, so an open stays mid-draw

# What the elements at `selectors` say (their text, or `attribute`; "" where there is none), joined
# by " · ": each change from now on once, in window.seen[key].
WATCH = """([key, selectors, attribute]) => {
  const say = (e) => (e ? (attribute ? e.getAttribute(attribute) : e.textContent) : "");
  const read = () => selectors.map((s) => say(document.querySelector(s))).join(" · ");
  const seen = [read()];
  new MutationObserver(() => read() !== seen.at(-1) && seen.push(read()))
    .observe(document.body, { attributes: true, childList: true, characterData: true, subtree: true });
  (window.seen ??= {})[key] = seen;
}"""


class Held:
    """The requests matching `pattern` while `holding`: each answered by the service when it is made
    (unless fetch=False) and handed to the page by `release`, or at once if holding ended while the
    service answered."""

    def __init__(self, page: Page, pattern: Any, fetch: bool = True) -> None:
        self.page = page
        self.fetch = fetch
        self.holding = True
        self.routes: list[tuple[Route, Any]] = []
        self.released: set[int] = set()
        page.route(pattern, self.handle)

    def handle(self, route: Route) -> None:
        if not self.holding:
            route.continue_()
            return
        self.routes.append((route, route.fetch() if self.fetch else None))
        if not self.holding:
            self.release(len(self.routes) - 1)

    def wait(self, n: int) -> None:
        """Until `n` requests are held (their answers fetched)."""
        deadline = time.monotonic() + WAIT_MS / 1000
        while len(self.routes) < n:
            assert time.monotonic() < deadline, f"{len(self.routes)} of {n} requests held"
            self.page.wait_for_timeout(20)  # Playwright hands the page's requests over meanwhile

    def release(self, i: int, **answer: Any) -> None:
        """Held request `i`'s answer (or `answer`: route.fulfill's arguments) to the page, once."""
        if i in self.released:
            return
        self.released.add(i)
        route, fetched = self.routes[i]
        if answer:
            route.fulfill(**answer)
        elif fetched is not None:
            route.fulfill(response=fetched)
        else:
            route.continue_()

    def release_all(self) -> None:
        """Holding ends: every held answer to the page, in the order asked."""
        self.holding = False
        for i in range(len(self.routes)):
            self.release(i)


@pytest.fixture(scope="module")
def context(browser: Browser) -> Iterator[BrowserContext]:
    # bypass_csp: Playwright's wait_for_function evaluates strings, which the dashboard's CSP refuses
    context = browser.new_context(bypass_csp=True, viewport={"width": 1400, "height": 1000})
    context.set_default_timeout(WAIT_MS)
    yield context
    context.close()


@pytest.fixture
def page(context: BrowserContext) -> Iterator[Page]:
    page = context.new_page()
    yield page
    page.close()


def goto(page: Page, live: BackgroundServer, run_id: int) -> None:
    """The dashboard at run `run_id`, not waiting for the page's load (a held script delays it)."""
    page.goto(f"{live.url}/?token={TOKENS['operator']}#run={run_id}", wait_until="commit")


def streams(page: Page) -> list[int]:
    """The runs whose event streams the page opens from now on."""
    opened: list[int] = []
    page.on("request", lambda r: (m := re.search(r"/api/runs/(\d+)/stream", r.url)) and opened.append(int(m[1])))
    return opened


def title_is(page: Page, run_id: int) -> None:
    page.wait_for_function(f"document.querySelector('#run-title').textContent.startsWith('Run #{run_id} ')")


def shown_epoch(page: Page, trainer: CollieClient, run_id: int, epoch: int) -> None:
    """A metrics row of the open run, through the service and the run's stream, is on the page."""
    trainer.post_metrics(run_id, MetricsIn(epoch=epoch, values={"safe_ratio": 0.5}))
    page.wait_for_function(f"document.querySelector('#run-epoch').textContent === '{epoch}'")


def seen(page: Page, key: str) -> list[str]:
    return page.evaluate(f"window.seen[{key!r}]")


def drawing(page: Page, live: BackgroundServer, run_id: int) -> tuple[list[int], Held]:
    """The run's page opened, its snapshot shown and its charts held (Plotly not yet loaded); the
    runs whose streams the page opens, as they open."""
    opened = streams(page)
    plotly = Held(page, PLOTLY, fetch=False)
    goto(page, live, run_id)
    plotly.wait(1)
    title_is(page, run_id)
    return opened, plotly


def only_stream_after(page: Page, trainer: CollieClient, plotly: Held, opened: list[int], run_id: int) -> None:
    """Plotly let through: the run shown opens its stream, shows its epochs, and no other opened one."""
    with page.expect_request(lambda r: f"/api/runs/{run_id}/stream" in r.url):
        plotly.release(0)
    shown_epoch(page, trainer, run_id, 3)
    assert opened == [run_id]


def test_a_run_opened_while_another_draws_gets_only_its_own_stream(
    page: Page, live: BackgroundServer, trainer: CollieClient
) -> None:
    """A's charts still draw when the operator opens B: A's stream must not start (its events
    would land on B's page, and nothing would ever close it)."""
    a, b = trainer.create_run(make_run_spec()), trainer.create_run(make_run_spec())
    opened, plotly = drawing(page, live, a.id)
    page.evaluate(f"window.location.hash = '#run={b.id}'")
    title_is(page, b.id)
    only_stream_after(page, trainer, plotly, opened, b.id)


def test_a_run_opened_again_while_it_draws_has_one_stream(
    page: Page, live: BackgroundServer, trainer: CollieClient
) -> None:
    """#run=A, a missing run, A again, all while A's first charts draw: one stream of A, not two
    (each metrics row would be drawn twice)."""
    a = trainer.create_run(make_run_spec())
    opened, plotly = drawing(page, live, a.id)
    page.evaluate("window.location.hash = '#run=99999'")
    page.wait_for_function("document.querySelector('#run-problem').textContent.startsWith('Run #99999: no such')")
    page.evaluate(f"window.location.hash = '#run={a.id}'")
    page.wait_for_selector("#run:not([hidden])")  # the second open's snapshot shown; its charts wait too
    only_stream_after(page, trainer, plotly, opened, a.id)


def test_a_failed_open_of_a_run_left_behind_does_not_hide_the_run_opened_since(
    page: Page, live: BackgroundServer, trainer: CollieClient
) -> None:
    a, b = trainer.create_run(make_run_spec()), trainer.create_run(make_run_spec())
    snapshot = Held(page, re.compile(rf"/api/dashboard/runs/{a.id}\?"), fetch=False)
    goto(page, live, a.id)
    snapshot.wait(1)  # A's page is asked for; the operator moves on to B
    page.evaluate(f"window.location.hash = '#run={b.id}'")
    title_is(page, b.id)
    with page.expect_response(lambda r: f"/api/dashboard/runs/{a.id}?" in r.url):
        snapshot.release(0, status=503, json={"detail": "the service is busy"})
    shown_epoch(page, trainer, b.id, 3)
    assert page.is_visible("#run") and page.is_hidden("#run-problem")
    title_is(page, b.id)


def test_a_late_answer_for_older_rollouts_does_not_redraw_them(
    page: Page, live: BackgroundServer, trainer: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec())

    def post(epoch: int) -> None:
        trainer.post_rollouts(
            run.id, RolloutsIn(epoch=epoch, rollouts=[Rollout(skill=[1.0, 0.0], xy=[[0, 0], [1, epoch]])])
        )

    post(2)
    goto(page, live, run.id)
    page.wait_for_selector("#map[data-epoch='2']", state="attached")
    latest = Held(page, re.compile(rf"/api/runs/{run.id}/rollouts\?"))
    post(4)
    latest.wait(1)  # the page asked for the latest rollouts: epoch 4's, held
    latest.holding = False
    page.evaluate(WATCH, ["map", ["#map"], "data-epoch"])
    post(6)
    page.wait_for_selector("#map[data-epoch='6']", state="attached")
    latest.release(0)  # epoch 4's answer, after epoch 6's
    post(8)
    page.wait_for_selector("#map[data-epoch='8']", state="attached")
    assert seen(page, "map") == ["2", "6", "8"]
    assert page.text_content("#map-title") == "skills · evaluation at epoch 8"  # was "skills": which one, unsaid


def test_late_labeling_answers_undo_neither_counts_nor_quality_settings_nor_a_discard(
    page: Page, live: BackgroundServer, trainer: CollieClient, operator: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec().model_copy(update={"redundancy": 2}))
    trainer.post_session(run.id, make_session(0, 4))
    labeler = CollieClient(live.url, operator.create_labeler("order-web").token)
    row = "#labelers-stats tr[data-labeler='order-web']"
    sessions = iter(range(1, 10))

    def reload() -> None:  # new queries: an event, and the page asks for the labeling panel again
        trainer.post_session(run.id, make_session(next(sessions), 1))

    def label() -> None:  # a label of r = 2 by one labeler makes no event of its own
        claim = labeler.claim(run.id)
        assert claim is not None
        labeler.submit(run.id, claim.query.query_id, 1)
        reload()

    def labels_shown(n: int) -> None:
        page.wait_for_function(f"document.querySelector(\"{row} td.labels\")?.textContent === '{n}'")

    goto(page, live, run.id)
    page.wait_for_selector("#quality[data-redundancy='2']", state="attached")
    page.wait_for_selector("#labeling-body dl")  # the panel drawn from the snapshot
    page.evaluate(WATCH, ["labels", ["#discard-message", f"{row} td.labels"], None])
    page.evaluate(WATCH, ["redundancy", ["#quality"], "data-redundancy"])
    labeling = Held(page, re.compile(rf"/api/dashboard/runs/{run.id}/labeling$"))
    label()
    labeling.wait(1)  # asked for after the first label: 1 label, r = 2
    page.fill("#quality-redundancy", "3")
    page.click("#quality-apply")
    page.wait_for_selector("#quality[data-redundancy='3']", state="attached")  # the PUT's answer
    labeling.wait(2)  # the refresh after it (or the page's 5 s one before it)
    labeling.release(0)  # asked for before the PUT's answer, arriving after it
    labeling.holding = False
    label()
    labels_shown(2)
    labeling.release_all()  # the rest: asked for before the answer that showed 2 labels
    label()
    labels_shown(3)

    labeling.holding = True
    held = len(labeling.routes)
    reload()
    labeling.wait(held + 1)  # asked for before the discard: 3 labels
    page.click(f"{row} button[data-discard]")  # arms
    with page.expect_response(lambda r: r.url.endswith("/discard")):
        page.click(f"{row} button[data-discard]")
    labeling.release(held)  # arriving after the discard's answer
    labeling.release_all()  # the reload after the discard, if it was held
    labels_shown(0)
    labeler.close()
    assert page.text_content("#discard-message").startswith("discarded 3 labels of order-web")
    shown = [said_count.split(" · ") for said_count in seen(page, "labels")]  # the page's own 5 s reloads may add some
    counts = [int(count) for said, count in shown if count and not said]
    assert counts == sorted(counts) and counts[-1] == 3  # the late answers' 1 never came back
    assert [count for said, count in shown if said] == ["0"]  # the discard's message only beside its result
    assert seen(page, "redundancy") == ["2", "3"]
