"""The labeling UI in a real browser against a real service."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path

import numpy as np
import pytest
import viser
from playwright.sync_api import Browser, expect

from collie.tasks import get_task

from .page import TIMEOUT_S, VIEWPORT, canvas_until, open_labeler, segment_id, wait_segment, wait_text
from .stack import Stack

pytestmark = pytest.mark.slow
# The UI silently ignores a label key pressed less than min_dwell_s after the segment appeared (a
# double tap), counted from just after the server flushed its first frame (presenter.py): on a busy
# machine the page may show the segment before that clock starts, so no sleep in the test is sure to
# outlast it. These UIs run without it (a key then always counts); test_tab_state tests the rule, and
# the dwell test below the rule in the browser, pressing until the key counts.
NO_DWELL = 0.0


def press(page: object, key: str) -> None:
    page.keyboard.press(key)  # type: ignore[attr-defined]


def effective(stack: Stack, run_id: int) -> dict[str, tuple[int, str]]:
    return {e.query_id: (e.label, e.labeler) for e in stack.trainer.effective_labels(run_id)}


def test_label_five_by_keys_then_undo(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 6, task="range_north")  # a task with all three classes
    token = stack.new_labeler("keys")
    page = open_labeler(browser, stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0).labeler_url(token))
    seen, shown = [], None
    for key in ["1", "2", "3", "3", "1"]:
        shown = wait_segment(page, shown)
        seen.append(shown)
        if len(seen) == 1:
            wait_text(page, "This session 0 / 6")
            page.screenshot(path=str(artifacts / "label-first-segment.png"))
        press(page, key)
    after = wait_segment(page, shown)  # the sixth segment
    assert after not in seen
    wait_text(page, "This session 5 / 6")
    expected = dict(zip(seen, [0, 1, 2, 2, 0], strict=True))
    assert {q: v for q, (v, _) in effective(stack, run.id).items()} == expected

    press(page, "u")  # the last label comes back to be labelled again
    assert wait_segment(page, after) == seen[-1]
    wait_text(page, "This session 4 / 6")
    page.screenshot(path=str(artifacts / "label-after-undo.png"))
    del expected[seen[-1]]
    labels = effective(stack, run.id)
    assert {q: v for q, (v, _) in labels.items()} == expected
    assert {who for _, who in labels.values()} == {"keys"}

    press(page, "3")  # relabel it; then the segment held before the undo is back
    assert wait_segment(page, seen[-1]) == after
    expected[seen[-1]] = 2
    assert {q: v for q, (v, _) in effective(stack, run.id).items()} == expected
    page.context.close()


def test_a_key_as_a_segment_appears_is_ignored_and_counts_once_it_has_been_watched(
    stack: Stack, browser: Browser
) -> None:
    """The dwell: a key pressed as a segment appears (the second half of a double tap, a held key)
    labels nothing; the same key once the segment has been on screen `min_dwell_s` labels it, with
    at least that long recorded, and a key pressed just after it does not label the next segment."""
    dwell = 6.0  # a key pressed as the page shows a segment reaches the service well within it, busy or not
    run = stack.post_run("point", 3, task="range_north")
    ui = stack.ui(run.id, min_dwell_s=dwell, min_played=0.0)
    page = open_labeler(browser, ui.labeler_url(stack.new_labeler("tapper")))

    def tap_until_labelled(key: str, count: int) -> None:
        """`key` every 0.3 s until the service holds `count` labels (the dwell's clock starts when
        the server sent the first frame, which on a busy machine may be after the page showed it)."""
        deadline = time.monotonic() + TIMEOUT_S
        while len(effective(stack, run.id)) < count:
            assert time.monotonic() < deadline, f"the key {key} never counted"
            press(page, key)
            time.sleep(0.3)

    first = wait_segment(page)
    press(page, "1")  # as it appears: within the dwell, or before its clock even started
    time.sleep(1.0)
    assert effective(stack, run.id) == {} and segment_id(page) == first
    tap_until_labelled("1", 1)
    [label] = stack.trainer.effective_labels(run.id)
    assert (label.query_id, label.label) == (first, 0)
    assert label.seconds is not None and label.seconds >= dwell

    # The next segment's dwell starts afresh: the last taps above, and a key as it appears, label
    # nothing. (Waiting out its dwell to label it too would only repeat the first segment's check;
    # test_label_five_by_keys_then_undo checks which label each key gives.)
    second = wait_segment(page, first)
    press(page, "3")
    time.sleep(1.0)
    assert {q: v for q, (v, _) in effective(stack, run.id).items()} == {first: 0}
    assert segment_id(page) == second
    page.context.close()


@pytest.mark.parametrize("env", ["point", "ant"])
def test_replay_canvas_is_not_blank(stack: Stack, browser: Browser, artifacts: Path, env: str) -> None:
    run = stack.post_run(env, 1, seed=3)
    page = open_labeler(browser, stack.ui(run.id).labeler_url(stack.new_labeler(f"canvas-{env}")))
    wait_segment(page)

    def centre(pixels: np.ndarray) -> np.ndarray:  # where the followed robot sits
        h, w, _ = pixels.shape
        return pixels[h // 2 - 40 : h // 2 + 40, w // 2 - 40 : w // 2 + 40]

    pixels = canvas_until(
        page, artifacts / f"replay-{env}.png", lambda p: p.std() > 10.0 and centre(p).std() > 10.0
    )  # a few replay frames
    assert pixels.std() > 10.0, f"the {env} replay canvas looks blank (std {pixels.std():.1f})"
    # the robot is drawn: the canvas centre is not floor-white/grey
    assert centre(pixels).std() > 10.0
    page.context.close()


def test_two_labelers_at_once_never_overlap(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 8, seed=5)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    pages = [open_labeler(browser, app.labeler_url(stack.new_labeler(name))) for name in ("ann", "bob")]
    current = [wait_segment(p) for p in pages]
    assert current[0] != current[1]
    seen: dict[str, list[str]] = {"ann": [current[0]], "bob": [current[1]]}
    for step in range(6):  # interleaved: each labels three while the other holds a claim
        i = step % 2
        press(pages[i], "2")
        current[i] = wait_segment(pages[i], current[i])
        seen[("ann", "bob")[i]].append(current[i])
        assert current[0] != current[1]
    pages[0].screenshot(path=str(artifacts / "two-labelers-ann.png"))
    pages[1].screenshot(path=str(artifacts / "two-labelers-bob.png"))
    labels = effective(stack, run.id)
    assert len(labels) == 6
    for name, ids in seen.items():
        labelled = {q for q, (_, who) in labels.items() if who == name}
        assert labelled == set(ids[:3])
    assert not set(seen["ann"]) & set(seen["bob"])
    for p in pages:
        p.context.close()


def test_wrong_token_is_refused_with_no_scene(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 2)
    app = stack.ui(run.id)
    page = open_labeler(browser, app.labeler_url("not-a-real-token"))
    wait_text(page, "The service refused this token")
    page.screenshot(path=str(artifacts / "wrong-token.png"))
    assert segment_id(page) is None
    assert app.sessions and all(s.scene.env is None for s in app.sessions.values())  # no scene was ever built
    assert stack.trainer.run(run.id).queue.leased == 0
    page.context.close()


def wait_until(condition: object, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:  # type: ignore[operator]
        time.sleep(0.05)
    assert condition(), "timed out"  # type: ignore[operator]


def test_next_segment_is_preloaded_and_a_closed_tab_releases_both(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0, release_grace_s=0.5)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("closer")))
    first = wait_segment(page)
    (session,) = app.sessions.values()
    wait_until(lambda: len(session.state.ahead) == 1)  # the next one is claimed and ready before any key
    preloaded = session.state.ahead[0].query.query_id
    assert preloaded != first and stack.trainer.run(run.id).queue.leased == 2
    press(page, "2")
    assert wait_segment(page, first) == preloaded
    wait_until(lambda: len(session.state.ahead) == 1)  # and the one after it
    page.context.close()
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 0)
    assert stack.trainer.run(run.id).queue.pending == 2
    assert [e.kind for e in stack.trainer.label_events(run.id)] == ["label"]  # a release is no skip


def test_the_counts_follow_labels_made_elsewhere_while_a_segment_is_on_screen(stack: Stack, browser: Browser) -> None:
    """Was: a tab showed "total 0" until its own next label, whatever other tabs and labelers did."""
    from collie.client import CollieClient

    run = stack.post_run("point", 4)
    app = stack.ui(run.id, lease_s=3.0)  # its claims renewed every second, and the counts read with them
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("watcher")))
    wait_segment(page)
    (session,) = app.sessions.values()
    wait_until(lambda: "total **0" in session.panels.progress.content)
    with CollieClient(stack.api, stack.new_labeler("elsewhere")) as other:
        claim = other.claim(run.id)
        assert claim is not None
        other.submit(run.id, claim.query.query_id, 1)
    wait_until(lambda: "total **1" in session.panels.progress.content)
    page.context.close()


def test_with_redundancy_a_lone_labeler_sees_their_own_count_move(stack: Stack, browser: Browser) -> None:
    """With two labelers per query a session counts a query once both labelled it: a lone labeler's
    "This session 0 / 3" never moved, however many they labelled. Their own count is said beside it."""
    run = stack.post_run("point", 3, redundancy=2)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("lone")))
    first = wait_segment(page)
    wait_text(page, "This session 0 / 3 settled (2 labelers each) · yours 0")
    press(page, "1")
    wait_segment(page, first)
    wait_text(page, "This session 0 / 3 settled (2 labelers each) · yours 1")
    page.context.close()


def view(client: viser.ClientHandle) -> np.ndarray | None:
    """The camera as the browser last reported it (orientation and position), None before its first report."""
    try:
        return np.concatenate([client.camera.wxyz, client.camera.position])
    except AssertionError:  # viser asserts a camera was reported before it answers
        return None


def settled_view(client: viser.ClientHandle) -> np.ndarray:
    """The camera once two reports half a second apart agree (a new scene aims it as it loads)."""
    wait_until(lambda: view(client) is not None)
    last = view(client)
    for _ in range(60):
        time.sleep(0.5)
        now = view(client)
        assert now is not None and last is not None
        if np.allclose(now, last, atol=1e-6):
            return now
        last = now
    raise AssertionError("the camera never settled")


def hold(page: object, key: str, seconds: float = 0.4) -> None:
    page.keyboard.down(key)  # type: ignore[attr-defined]
    time.sleep(seconds)  # viser's camera keys move the view for as long as they are held
    page.keyboard.up(key)  # type: ignore[attr-defined]


def test_frame_and_skip_keys_leave_the_north_up_view_alone(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("keys-view")))
    first = wait_segment(page)
    (session,) = app.sessions.values()
    start = settled_view(session.client)
    hold(page, "j")  # a frame key pauses: from here only the frame keys change the frame
    wait_until(lambda: not session.player.playing)
    frame = session.player.position  # at most the second-to-last frame, so one more fits
    hold(page, "l")
    wait_until(lambda: session.player.position == frame + 1)
    hold(page, "j")
    wait_until(lambda: session.player.position == frame)
    hold(page, "x")
    wait_segment(page, first)
    assert [(e.query_id, e.kind) for e in stack.trainer.label_events(run.id)] == [(first, "skip")]
    time.sleep(1.0)  # a camera the keys had moved would have been reported by now
    assert np.allclose(view(session.client), start, atol=1e-6)
    hold(page, "ArrowLeft")  # control: viser's own camera key does turn the view, and this test sees it
    wait_until(lambda: not np.allclose(view(session.client), start, atol=1e-3))
    page.context.close()


def test_a_revoked_labeler_is_told_without_pressing_a_key(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, lease_s=3.0)  # the tab renews its claims every lease_s / 3 while one is on screen
    created = stack.operator.create_labeler("revoked-mid-segment")
    page = open_labeler(browser, app.labeler_url(created.token))
    wait_segment(page)
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # on screen and preloaded
    stack.operator.revoke(created.id)
    assert stack.trainer.run(run.id).queue.leased == 0  # back in the pool at once
    wait_text(page, "The service refused this token")  # at its next renewal
    assert segment_id(page) is None  # the segment left the screen
    page.context.close()


def test_waiting_screen_then_new_queries_appear(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 0)
    page = open_labeler(browser, stack.ui(run.id).labeler_url(stack.new_labeler("waiter")))
    wait_text(page, "Nothing to label right now")
    page.screenshot(path=str(artifacts / "waiting.png"))
    stack.post_session(run.id, "point", 1, 2, seed=7)
    assert wait_segment(page).startswith("1-")  # no reload
    page.context.close()


def test_unbuildable_model_can_be_skipped(stack: Stack, browser: Browser, artifacts: Path) -> None:
    broken = stack.post_run("ant", 2, rollout_env="point")  # point's states: Ant's model cannot pose them
    page = open_labeler(
        browser, stack.ui(broken.id, min_dwell_s=NO_DWELL, min_played=0.0).labeler_url(stack.new_labeler("skipper"))
    )
    first = wait_segment(page)
    wait_text(page, "cannot be replayed")
    page.screenshot(path=str(artifacts / "unbuildable-model.png"))
    press(page, "1")  # a label is refused on a segment that cannot be shown
    press(page, "x")
    wait_segment(page, first)
    events = stack.trainer.label_events(broken.id)
    assert [(e.query_id, e.kind) for e in events] == [(first, "skip")]
    page.context.close()


def test_unreachable_service_is_reported(stack: Stack, browser: Browser) -> None:
    from labeling_ui.app import LabelingApp
    from labeling_ui.session import UiConfig

    app = LabelingApp(UiConfig(api="http://127.0.0.1:9", retry_max_s=1.0), port=0)
    stack.apps.append(app)
    page = open_labeler(browser, app.labeler_url("any-token"))
    wait_text(page, "unreachable")
    wait_text(page, "at http://127.0.0.1:9 does not answer")  # names the address it tried
    assert segment_id(page) is None and all(s.scene.env is None for s in app.sessions.values())
    wait_text(page, "your token is checked once it answers")  # not signed in yet: no labeling control
    assert (
        page.get_by_text("U · Undo last label").count() == 0
        or not page.get_by_text("U · Undo last label").first.is_visible()
    )
    page.context.close()


def test_a_label_the_service_is_slow_to_take_is_said_to_be_on_its_way(stack: Stack, browser: Browser) -> None:
    """A key is answered in milliseconds; when the service is slow (its database busy) the labeler
    sees the label is on its way, not a key that seems ignored, and then the next segment."""
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("slow")))
    first = wait_segment(page)
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # preloaded: no write of the tab's pending
    busy = sqlite3.connect(stack.service.app.state.db.url.removeprefix("sqlite:///"), isolation_level=None)
    busy.execute("BEGIN EXCLUSIVE")  # every write waits (the service's busy timeout is 5 s)
    try:
        press(page, "2")
        wait_text(page, "Sending your label", timeout_s=15)  # the label waits while the lock is held
        assert segment_id(page) == first
    finally:
        busy.execute("COMMIT")
        busy.close()
    wait_segment(page, first)
    expect(page.get_by_text("Sending your label")).to_have_count(0, timeout=TIMEOUT_S * 1000)
    assert {q: v for q, (v, _) in effective(stack, run.id).items()} == {first: 1}
    page.context.close()


def test_sign_in_field_and_reload_stays_signed_in(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 2)
    app = stack.ui(run.id, release_grace_s=30.0)  # however slow the reload, the claim waits for it
    page = open_labeler(browser, app.url)  # no token in the URL
    wait_text(page, "Paste the labeler token")
    field = page.get_by_role("textbox").first
    field.fill(stack.new_labeler("typist"))
    field.press("Enter")  # as a click on Sign in
    first = wait_segment(page)
    wait_text(page, "signed in as")
    page.screenshot(path=str(artifacts / "signed-in-by-field.png"))
    page.reload()  # the token is remembered in the page's storage; the claim is still ours
    assert wait_segment(page) == first
    page.context.close()


def test_a_skipped_segment_that_comes_round_again_is_said_to(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 2)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("round-skipper")))
    first = wait_segment(page)
    press(page, "x")
    second = wait_segment(page, first)
    press(page, "x")
    assert wait_segment(page, second) == first  # nothing else to show: the first skipped one again
    wait_text(page, "Skipped before")
    wait_text(page, f"{first} is back: the others are labelled or skipped")
    page.context.close()


def test_label_keys_work_after_a_click_on_a_replay_control(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 3, task="range_north")
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("clicker")))
    first = wait_segment(page)
    loop = page.get_by_label("Loop")
    loop.click()  # the checkbox has focus now; viser's page alone would ignore the next key
    assert page.evaluate("document.activeElement?.type") == "checkbox"
    press(page, "3")
    second = wait_segment(page, first)
    frame_box = page.locator(".mantine-NumberInput-input").first
    frame_box.click()  # it shows the frame and takes no typing: a digit is a label
    press(page, "1")
    wait_segment(page, second)
    assert {e.query_id: e.label for e in stack.trainer.effective_labels(run.id)} == {first: 2, second: 0}
    assert not loop.is_checked()  # the click itself did what it does
    page.context.close()


def test_a_narrow_window_opens_with_the_context_column_minimized(stack: Stack, browser: Browser) -> None:
    # Two segments per tab (the one shown and the one preloaded): a tab never waits for the claims of
    # the one closed before it, which the UI holds release_grace_s for a reload of that tab.
    run = stack.post_run("point", 6)
    url = stack.ui(run.id).labeler_url(stack.new_labeler("narrow"))
    description = get_task("north", "point").description
    # One load per width: the UI reads the width the page reports as it opens (window.innerWidth in
    # the tab's handoff, labeling_ui/browser.py), before it shows anything; no race is left to repeat
    # for (the camera's first report decided it once, and 3 of 7 loads at 800 px kept the column).
    for width, shown in ((390, False), (800, False), (VIEWPORT["width"], True)):
        context = browser.new_context(viewport={"width": width, "height": 600})
        context.set_default_timeout(TIMEOUT_S * 1000)
        page = context.new_page()
        page.goto(url)
        wait_segment(page)
        # a phone: said, not hidden (was: the controls covered the robot without a word)
        phone = page.get_by_text("Made for a computer screen")
        if width < 600:
            phone.first.wait_for()
        else:
            assert phone.count() == 0
        # the column minimizes as the tab opens (the window width the browser handed over); the task's
        # text is sent before the progress line, so once that is on screen the text is on the page
        # unless its column is minimized (which leaves it out of the page)
        wait_text(page, "This session")
        text = page.get_by_text(description).first
        if shown:
            text.wait_for(state="attached")
            expect(text, f"width {width}").to_be_visible(timeout=TIMEOUT_S * 1000)
        else:
            expect(text, f"width {width}").to_be_hidden(timeout=TIMEOUT_S * 1000)
        context.close()


def test_a_labeler_whose_only_run_ended_is_told_no_run_takes_labels(stack: Stack, browser: Browser) -> None:
    """Was "No run is open on the service yet." (as if one were coming), after a reload too."""
    run = stack.post_run("point", 2)
    token = stack.operator.create_labeler("scoped-ended", runs=[run.id]).token  # this run only
    stack.operator.stop(run.id)
    stack.trainer.set_status(run.id, "finished")
    page = open_labeler(browser, stack.ui(min_dwell_s=NO_DWELL).labeler_url(token))  # no run pinned
    wait_text(page, "No run on the service takes labels now.")
    assert "yet" not in page.inner_text("body")
    page.context.close()


def test_a_stopped_run_leaves_the_screen_and_its_preloaded_segment_is_not_shown(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("late")))
    wait_segment(page)
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # on screen and preloaded
    stack.operator.stop(run.id)
    stack.trainer.set_status(run.id, "finished")  # the trainer acts on the stop
    press(page, "2")
    wait_text(page, f"run {run.id} is stopped: it takes no more labels")  # not "finished"
    wait_text(page, f"Run {run.id} (point, north) is stopped")  # the waiting screen, from the first refusal
    assert segment_id(page) is None  # neither the labelled one nor the preloaded one
    assert "finished" not in page.inner_text("body")
    assert stack.trainer.label_events(run.id) == []
    page.context.close()


def test_a_paused_run_says_so_beside_its_segments(stack: Stack, browser: Browser) -> None:
    """Was: a paused run looked like a running one while segments remained."""
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("in-a-pause")))
    first = wait_segment(page)
    assert "paused" not in page.inner_text("body")
    stack.operator.pause(run.id)
    press(page, "2")
    wait_segment(page, first)
    wait_text(page, "The run is paused by an operator")
    page.context.close()


def test_a_run_that_ends_while_its_segment_is_on_screen_takes_it_away_at_once(stack: Stack, browser: Browser) -> None:
    """Was: the segment stayed, every key live, until the next key (whose label was then refused:
    "Not recorded") or the lease renewal up to 20 s later. The tab's title says what it shows."""
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("onlooker")))
    wait_segment(page)
    assert page.title() == f"Label · run {run.id} · collie labeling"  # was "Viser"
    wait_text(page, "units across · the segment runs from (")  # the inset's scale and where it lies
    stack.operator.stop(run.id)
    stack.trainer.set_status(run.id, "finished")  # the trainer acts on the stop
    wait_text(page, "Nothing more to label in this run.", timeout_s=10.0)  # no key pressed, well before a renewal
    wait_text(page, f"run {run.id} is stopped: it takes no more labels")  # the notice of why
    assert segment_id(page) is None and page.title() == "Run over · collie labeling"
    body = page.inner_text("body")
    assert "right now" not in body and "Undo last label" not in body  # nothing will come, and no undo is taken
    assert stack.trainer.label_events(run.id) == []
    page.context.close()


def test_a_label_on_a_run_being_stopped_counts_and_its_preload_is_not_shown(stack: Stack, browser: Browser) -> None:
    """The trainer has not acted on the stop yet, so the label on screen still lands; the segment
    preloaded before the stop used to come next, until a lease renewal 20 s later dropped it."""
    run = stack.post_run("point", 3)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0, lease_s=600.0)  # no renewal within the test
    page = open_labeler(browser, app.labeler_url(stack.new_labeler("stopping")))
    first = wait_segment(page)
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # on screen and preloaded
    stack.operator.stop(run.id)  # the trainer goes on a moment: the run is "stopping"
    press(page, "2")
    wait_text(page, f"Run {run.id} (point, north) is stopping")
    assert segment_id(page) is None
    assert [(e.query_id, e.kind) for e in stack.trainer.label_events(run.id)] == [(first, "label")]
    page.context.close()


def test_a_labeler_taken_off_the_run_moves_on_and_stays_signed_in(stack: Stack, browser: Browser) -> None:
    run, other = stack.post_run("point", 3), stack.post_run("point", 3)
    created = stack.operator.create_labeler("moved", runs=[run.id])
    app = stack.ui(lease_s=3.0)  # not pinned: the tab picks the runs its token may label
    page = open_labeler(browser, app.labeler_url(created.token))
    wait_segment(page)
    wait_text(page, f"run {run.id} · point")
    stack.operator.set_labeler_runs(created.id, [other.id])
    wait_text(page, f"run {other.id} · point")  # at the next claim renewal (lease_s / 3)
    assert "refused this token" not in page.inner_text("body")  # still signed in
    page.context.close()
