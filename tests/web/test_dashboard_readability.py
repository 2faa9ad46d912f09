"""What the run page says and draws, read as a person reads it, in Debian's Chromium against a live
service: labelled segments show their class's colour on the skill map, counts of one are singular,
and a run with one evaluation has a sensible epoch axis."""

from __future__ import annotations

import io
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from PIL import Image
from service.conftest import TOKENS, make_run_spec, make_session

from backend.server import BackgroundServer
from collie.class_colours import STRONG, to_rgb
from collie.client import CollieClient
from collie.schemas import EnvDims, MetricsIn, Rollout, RolloutsIn, RunRead

from .conftest import operator_page

WAIT_MS = 30_000
DIMS = EnvDims(obs_dim=4, nq=2, nv=2, horizon=20, skill_dim=2)  # 20 states a segment, as a real run's
BAD_Y = -12.0  # the bad segment's row, clear of the others and of the trajectories


@pytest.fixture(scope="module")
def run(live: BackgroundServer, trainer: CollieClient, operator: CollieClient) -> RunRead:
    """Five segments labelled by one labeler (1 label / min over the last five minutes), the first bad
    and alone at the bottom of the map; one evaluation, at epoch 0."""
    created = trainer.create_run(make_run_spec(dims=DIMS))
    post = make_session(0, 5, DIMS)
    for k, q in enumerate(post.queries):
        y = BAD_Y if k == 0 else 4.0 * k
        q.xy = [[-8.0 + 0.4 * i, y] for i in range(DIMS.horizon)]
    trainer.post_session(created.id, post)
    with CollieClient(live.url, operator.create_labeler("reader").token) as client:
        for _ in range(5):
            query = client.claim(created.id).query.query_id  # type: ignore[union-attr]
            client.submit(created.id, query, 0 if query == "0-0" else 1)
    trainer.post_metrics(created.id, MetricsIn(epoch=0, values={"safe_ratio": 0.5, "n_labels": 5.0}))
    trainer.post_rollouts(created.id, RolloutsIn(epoch=0, rollouts=[Rollout(skill=[1.0, 0.0], xy=[[0, 0], [1, 1]])]))
    return created


@pytest.fixture(scope="module")
def page(live: BackgroundServer, browser: Any, run: RunRead) -> Iterator[Any]:
    with operator_page(browser, f"{live.url}/?token={TOKENS['operator']}#run={run.id}", wait_ms=WAIT_MS) as page:
        page.wait_for_function("document.querySelector('#map').dataset.labelled === '5'")
        page.wait_for_function("document.querySelector('#curves').dataset.points === '1'")
        yield page


def test_a_labelled_segment_reads_as_its_class_colour(page: Any) -> None:
    """The pixels drawn around the bad segment are mostly its class's red, hardly any near-black."""
    box = page.evaluate(
        """([x0, x1, y]) => {
          const map = document.querySelector('#map');
          const { xaxis, yaxis, _size } = map._fullLayout;
          const r = map.getBoundingClientRect();
          const px = (x) => r.left + _size.l + xaxis.l2p(x), py = (v) => r.top + _size.t + yaxis.l2p(v);
          return { x: px(x0) - 8, y: py(y) - 8, width: px(x1) - px(x0) + 16, height: 16 };
        }""",
        [-8.0, -8.0 + 0.4 * (DIMS.horizon - 1), BAD_Y],
    )
    pixels = np.asarray(Image.open(io.BytesIO(page.screenshot(clip=box))).convert("RGB")).reshape(-1, 3).astype(int)
    background = (np.abs(pixels - pixels.max(axis=0)).sum(axis=1) < 40) | (pixels.min(axis=1) > 200)
    drawn = pixels[~background]
    assert len(drawn) > 200  # the segment is there
    assert to_rgb(STRONG[0])[0] > 200  # bad is red: red pixels, or their blends into the pale background
    red = drawn[:, 0] - drawn[:, 1:].max(axis=1) > 50
    dark = drawn.max(axis=1) < 90
    assert red.mean() > 0.7, f"only {red.mean():.0%} of the segment's pixels are its class colour"
    assert dark.mean() < 0.05, f"{dark.mean():.0%} of the segment's pixels are near-black"


def test_counts_of_one_are_singular(page: Any) -> None:
    assert page.text_content("#curves-note") == "1 evaluation"
    pace = page.locator("#labeling-body dt:text-is('pace') + dd").inner_text()
    assert pace.startswith("1 label / min")


def x_ranges(page: Any) -> list[list[float]]:
    return page.evaluate(
        "Object.entries(document.querySelector('#curves')._fullLayout)"
        ".filter(([k]) => /^xaxis\\d*$/.test(k)).map(([, a]) => a.range)"
    )


def test_the_epoch_axis_is_sensible_for_one_evaluation_and_then_more(
    page: Any, trainer: CollieClient, run: RunRead
) -> None:
    """Last in the module: it posts a second evaluation."""
    ranges = x_ranges(page)
    assert ranges
    assert all(low == 0 and 1 <= high <= 2 for low, high in ranges)  # epoch 0 in view, no negative epochs
    ticks = page.eval_on_selector_all("#curves .xtick text", "ts => ts.map(t => t.textContent)")
    assert ticks and all(t.isdigit() for t in ticks)  # whole epochs
    trainer.post_metrics(run.id, MetricsIn(epoch=6, values={"safe_ratio": 0.6, "n_labels": 5.0}))
    page.wait_for_function("document.querySelector('#curves').dataset.points === '2'")
    assert all(-0.01 < low <= 0 and 6 <= high < 7 for low, high in x_ranges(page))  # the data's span, from 0
