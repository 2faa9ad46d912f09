"""Labeling all day, in a real browser against a real service: per-tab identity, stale tabs, a label
only after the segment was seen, my labels across reloads, honest waiting, instructions, playback
preferences and the reset-view control."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from urllib.parse import quote

import pytest
from playwright.sync_api import Browser, Page
from stalling_proxy import stalling_relay

from collie.client import CollieClient
from collie.schemas import MetricsIn
from labeling_ui.app import LabelingApp
from labeling_ui.browser import TAB_KEY
from labeling_ui.session import UiConfig

from .page import TIMEOUT_S, VIEWPORT, canvas_until, segment_id, wait_segment, wait_text
from .stack import TOKENS, Stack
from .test_labeling_ui import NO_DWELL, effective, press, wait_until
from .test_watch import evaluation

pytestmark = pytest.mark.slow


def tab(context: object, url: str) -> Page:
    """A new tab in the same browser profile (tabs share localStorage, each has its sessionStorage)."""
    page = context.new_page()  # type: ignore[attr-defined]
    page.goto(url)
    return page


def profile(browser: Browser) -> object:
    context = browser.new_context(viewport=VIEWPORT)
    context.set_default_timeout(TIMEOUT_S * 1000)
    return context


def title(page: Page) -> str:
    return page.get_by_text("collie · labeling").first.inner_text()


def test_identity_is_per_tab(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 4)
    app = stack.ui(run.id, release_grace_s=30.0)
    context = profile(browser)
    ann = tab(context, app.labeler_url(stack.new_labeler("ann")))
    first = wait_segment(ann)
    wait_text(ann, "signed in as ann")
    # the dashboard's watch link (operator token) opened in another tab of the same browser...
    op = tab(context, f"{app.url}?token={quote(TOKENS['operator'])}&watch={run.id}")
    wait_text(op, "operator")
    # ...and a tab with a wrong token
    wrong = tab(context, app.labeler_url("not-a-real-token"))
    wait_text(wrong, "The service refused this token")
    ann.reload()  # still ann, same segment: neither tab changed who this one is
    assert wait_segment(ann) == first
    wait_text(ann, "signed in as ann")
    assert "operator" not in title(ann)
    ann.screenshot(path=str(artifacts / "identity-after-reload.png"))
    # a bare URL in a new tab knows nobody: the token is not shared through the profile's storage
    bare = tab(context, app.url)
    wait_text(bare, "Paste the labeler token")
    labelers = {e.labeler for e in stack.trainer.label_events(run.id)}
    assert labelers <= {"ann"}
    context.close()  # type: ignore[attr-defined]


def test_a_change_of_identity_in_one_tab_is_loud(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 2)
    app = stack.ui(run.id)
    context = profile(browser)
    page = tab(context, app.labeler_url(stack.new_labeler("cara")))
    wait_text(page, "signed in as cara")
    page.get_by_text("Account").first.click()
    page.get_by_role("button", name="Sign out").click()
    wait_text(page, "Signed out")
    wait_text(page, "not signed in")
    assert page.get_by_text("signed in as cara").count() == 0
    page.get_by_role("textbox").first.fill(stack.new_labeler("dave"))
    page.get_by_role("button", name="Sign in").click()
    wait_text(page, "signed in as dave")
    wait_text(page, "This tab was signed in as cara")
    context.close()  # type: ignore[attr-defined]


def test_a_stale_tab_never_labels_what_it_no_longer_holds(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 6, seed=11)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    token = stack.new_labeler("erin")
    context = profile(browser)
    front = tab(context, app.labeler_url(token))
    shown = wait_segment(front)
    # another UI of the same labeler (or a tab of another UI) labels the segment meanwhile
    with CollieClient(stack.api, token) as other:
        other.submit(run.id, shown, 1)
    press(front, "2")
    wait_text(front, "no longer holds")
    wait_segment(front, shown)  # the refused tab moves on
    # two tabs of this labeler never show one segment: the newest tab to show it labels it
    back = tab(context, app.labeler_url(token))
    behind = wait_segment(back)
    assert behind != segment_id(front) or "another of your tabs" in front.inner_text("body")
    for page in (back, front):
        current = segment_id(page)
        press(page, "1")
        wait_segment(page, current)
    events = stack.trainer.label_events(run.id)
    assert [e.query_id for e in events if e.query_id == shown] == [shown]  # no revision of it
    assert all(e.revises_event_id is None for e in events), "a tab relabelled a segment it did not hold"
    context.close()  # type: ignore[attr-defined]


def test_a_duplicated_tab_labels_segments_of_its_own(stack: Stack, browser: Browser) -> None:
    """A tab opened with window.open from a labeler's tab (what "Duplicate tab" does too) starts
    with a copy of its sessionStorage, tab id included: it must get an id and segments of its own,
    and the original keeps what it shows."""
    run = stack.post_run("point", 8, seed=13)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0, release_grace_s=30.0)
    context = profile(browser)
    original = tab(context, app.labeler_url(stack.new_labeler("dup")))
    first = wait_segment(original)
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # on screen and preloaded
    copied = original.evaluate(f"sessionStorage.getItem({TAB_KEY!r})")
    with original.expect_popup() as opened:
        original.evaluate("window.open(location.href)")
    duplicate = opened.value
    duplicate.set_default_timeout(TIMEOUT_S * 1000)
    theirs = wait_segment(duplicate)
    wait_text(duplicate, "This session")  # the duplicate's worker is past its claims
    ids = [p.evaluate(f"sessionStorage.getItem({TAB_KEY!r})") for p in (original, duplicate)]
    assert ids[0] == copied != ids[1], ids  # the original keeps its id, the copy got one of its own
    assert theirs != first and segment_id(original) == first  # nothing moved off the original
    for page, key, shown in ((original, "1", first), (duplicate, "2", theirs)):
        press(page, key)
        wait_segment(page, shown)
    assert effective(stack, run.id) == {first: (0, "dup"), theirs: (1, "dup")}
    events = [(e.query_id, e.kind, e.revises_event_id) for e in stack.trainer.label_events(run.id)]
    assert sorted(events) == sorted([(first, "label", None), (theirs, "label", None)])
    now = segment_id(duplicate)
    duplicate.reload()  # the copy's own id was kept in its sessionStorage: its segment comes back
    assert wait_segment(duplicate) == now
    context.close()  # type: ignore[attr-defined]


def test_a_tab_whose_segment_another_tab_took_over_moves_on(stack: Stack, browser: Browser) -> None:
    """Two open tabs going by one id (what a duplicated tab was before it got its own) share that
    id's claims: the one that shows a segment last labels it, and the other drops it with a notice
    and moves on by itself (it used to stay on it, refusing every key)."""
    run = stack.post_run("point", 6, seed=17)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    app.tab_id = lambda _, tab: tab  # type: ignore[method-assign]  # the copy keeps the original's id
    context = profile(browser)
    original = tab(context, app.labeler_url(stack.new_labeler("shared-id")))
    first = wait_segment(original)
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # on screen and preloaded
    with original.expect_popup() as opened:
        original.evaluate("window.open(location.href)")
    duplicate = opened.value
    duplicate.set_default_timeout(TIMEOUT_S * 1000)
    assert wait_segment(duplicate) == first  # the service hands the id's first claim to the copy
    wait_text(original, "Moved to another tab")
    moved_on = wait_segment(original, first)
    press(original, "1")
    wait_segment(original, moved_on)
    assert effective(stack, run.id) == {moved_on: (0, "shared-id")}
    context.close()  # type: ignore[attr-defined]


def test_a_label_counts_only_after_the_segment_played(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 2, seed=2)
    # 20 frames at 1 fps: 19 s before it counts as seen, a margin for the first key. The service's
    # player runs on its own clock, and under load the browser may show the segment's id seconds
    # after its first frame was sent.
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, fps=1.0)
    context = profile(browser)
    page = tab(context, app.labeler_url(stack.new_labeler("fay")))
    first = wait_segment(page)
    press(page, "2")
    wait_text(page, "Watch it first")
    assert segment_id(page) == first and stack.trainer.label_events(run.id) == []
    # the key was refused: the rest plays at 4x (the labeler's own speed control), not 19 s at 1x
    page.get_by_role("button", name="4×").click()
    wait_text(page, "Speed 4×")
    (session,) = app.sessions.values()
    deadline = time.monotonic() + 60
    while not session.state.shown.seen(1.0) and time.monotonic() < deadline:  # type: ignore[union-attr]
        time.sleep(0.1)
    press(page, "2")
    wait_segment(page, first)
    (event,) = stack.trainer.label_events(run.id)
    assert event.query_id == first and event.seconds is not None and event.seconds > 0
    context.close()  # type: ignore[attr-defined]


def test_undo_after_a_reload_withdraws_this_tabs_label_not_another_tabs(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 6, seed=5)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0, release_grace_s=30.0)
    context = profile(browser)
    url = app.labeler_url(stack.new_labeler("two-tabs-undo"))
    first, second = tab(context, url), tab(context, url)
    mine = wait_segment(first)
    press(first, "1")
    wait_until(lambda: any(e.query_id == mine for e in stack.trainer.label_events(run.id)))
    theirs = wait_segment(second)
    press(second, "2")  # the labeler's newest label now: the other tab's
    wait_until(lambda: any(e.query_id == theirs for e in stack.trainer.label_events(run.id)))
    first.reload()
    wait_segment(first)
    press(first, "u")
    wait_until(lambda: stack.trainer.label_events(run.id)[-1].kind == "undo")
    assert stack.trainer.label_events(run.id)[-1].query_id == mine != theirs
    context.close()  # type: ignore[attr-defined]


def test_my_labels_survive_a_reload_and_can_be_relabelled(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 5, seed=4)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0, release_grace_s=30.0)
    context = profile(browser)
    page = tab(context, app.labeler_url(stack.new_labeler("gil")))
    labelled, shown = [], None
    for key in ("1", "2"):
        shown = wait_segment(page, shown)
        labelled.append(shown)
        press(page, key)
    shown = wait_segment(page, shown)
    page.reload()
    assert wait_segment(page) == shown
    page.get_by_text("My labels").first.click()
    wait_text(page, "2 labelled in this run")
    for query_id in labelled:
        wait_text(page, query_id)
    page.screenshot(path=str(artifacts / "my-labels.png"))
    press(page, "u")  # undo after the reload: the newest label, kept by the service
    assert wait_segment(page, shown) == labelled[-1]
    kinds = [(e.query_id, e.kind) for e in stack.trainer.label_events(run.id)]
    assert kinds[-1] == (labelled[-1], "undo")
    wait_text(page, "1 labelled in this run (1 more undone)")  # as the totals count it
    press(page, "1")
    before = wait_segment(page, labelled[-1])
    # pick one from the list to replay it and relabel it: a revision event
    page.get_by_role("button", name="Replay and relabel").click()
    picked = wait_segment(page, before)
    assert picked in labelled
    wait_text(page, "relabel")
    press(page, "2")
    wait_segment(page, picked)
    revision = [e for e in stack.trainer.label_events(run.id) if e.query_id == picked][-1]
    assert revision.kind == "label" and revision.value == 1 and revision.revises_event_id is not None
    context.close()  # type: ignore[attr-defined]


def test_waiting_is_honest_and_shows_the_latest_skills(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("ant", 0)
    stack.trainer.post_rollouts(run.id, evaluation(3, 2))
    for epoch in (1, 2, 3):
        stack.trainer.post_metrics(run.id, MetricsIn(epoch=epoch, values={"loss": 1.0}))
        time.sleep(0.3)
    app = stack.ui(run.id)
    context = profile(browser)
    page = tab(context, app.labeler_url(stack.new_labeler("hal")))
    wait_text(page, "Nothing to label right now")
    wait_text(page, "at epoch 3")
    wait_text(page, "The run's latest evaluation")
    pixels = canvas_until(page, artifacts / "waiting-skills.png", lambda p: p.std() > 10.0)
    assert pixels.std() > 10.0  # not a blank screen
    assert "being labelled elsewhere" not in page.inner_text("body")
    stack.operator.stop(run.id)
    stack.trainer.post_metrics(run.id, MetricsIn(epoch=4, values={"loss": 1.0}))  # a stream event wakes the tab
    wait_text(page, "stopping")
    assert "finished" not in page.inner_text("body")
    wait_text(page, "This run takes no more labels")
    assert "New segments appear here" not in page.inner_text("body")
    context.close()  # type: ignore[attr-defined]


def test_instructions_rule_and_a_class_the_task_cannot_give(stack: Stack, browser: Browser, artifacts: Path) -> None:
    run = stack.post_run("point", 2)  # north: nothing is ever good
    html = '<img src=x onerror="window.pwned=1">'  # an operator's text is shown, never run
    stack.operator.set_instructions(run.id, f"Judge only the last second of each segment. {html}")
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    context = profile(browser)
    page = tab(context, app.labeler_url(stack.new_labeler("ivy")))
    first = wait_segment(page)
    wait_text(page, "Judge only the last second of each segment.")
    wait_text(page, html)
    assert page.evaluate("window.pwned") is None and page.locator("img[src='x']").count() == 0
    wait_text(page, "bad if any state is bad")
    good = page.get_by_role("button", name="3 · Good (not in this task)")
    good.wait_for()
    assert good.is_disabled()
    press(page, "3")
    wait_text(page, "never calls a state good")
    assert segment_id(page) == first and stack.trainer.label_events(run.id) == []
    page.screenshot(path=str(artifacts / "instructions.png"))
    context.close()  # type: ignore[attr-defined]


def test_speed_and_loop_persist_per_labeler(stack: Stack, browser: Browser) -> None:
    run = stack.post_run("point", 2)
    app = stack.ui(run.id, release_grace_s=30.0)
    token = stack.new_labeler("jo")
    context = profile(browser)
    page = tab(context, app.labeler_url(token))
    wait_segment(page)
    wait_text(page, "Speed 1×")
    page.get_by_role("button", name="2×").click()
    wait_text(page, "Speed 2×")
    page.get_by_text("Loop").first.click()
    (session,) = app.sessions.values()
    deadline = time.monotonic() + 30
    while session.player.loop and time.monotonic() < deadline:
        time.sleep(0.1)

    def stored() -> str:  # the browser has the new preferences (they travel after the player changed)
        return page.evaluate(
            "Object.keys(localStorage).filter(k => k.includes('collie-prefs-jo'))"
            ".map(k => localStorage.getItem(k)).join(' ')"
        )

    while '"loop": false' not in stored() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert '"loop": false' in stored(), stored()
    page.reload()
    wait_segment(page)
    wait_text(page, "Speed 2×")
    live = [s for s in app.sessions.values() if s.who == "jo" and not s.closed.is_set()]
    assert live and live[0].player.speed == 2.0 and live[0].player.loop is False
    page.get_by_role("button", name="Reset view (north up)").click()  # the control is there and answers
    context.close()  # type: ignore[attr-defined]


def test_a_page_that_reconnects_keeps_its_tab_id_while_its_old_connection_looks_open() -> None:
    """After a network blip the page's new connection arrives while the old one is half-open (its
    page cannot answer the app's question, which counts as open): the page load's own id says it is
    the same page, so it keeps its tab id, its claims and its undo history; a copy of the tab has
    another page id and gets a tab id of its own."""
    import threading
    from types import SimpleNamespace

    from labeling_ui.app import LabelingApp
    from labeling_ui.session import UiConfig

    app = LabelingApp(UiConfig(api="http://127.0.0.1:9"), port=0, warm=())
    try:
        tab, page = "tab-" + "a" * 24, "page-" + "b" * 24
        old = SimpleNamespace(page=page, closed=threading.Event(), page_open=lambda timeout_s: True)
        app._tabs[tab] = old  # type: ignore[assignment]
        back = SimpleNamespace(page=page, closed=threading.Event(), page_open=lambda timeout_s: True)
        assert app.tab_id(back, tab) == tab  # type: ignore[arg-type]
        copy = SimpleNamespace(page="page-" + "c" * 24)
        assert app.tab_id(copy, tab) != tab  # type: ignore[arg-type]
    finally:
        app.stop()


def test_a_reload_while_a_label_is_on_its_way_loses_nothing_and_stalls_nothing(stack: Stack, browser: Browser) -> None:
    """The labeler presses a key, the network holds the label, and they reload. The reloaded tab
    gets the segment back (the label has not arrived); when the old page's label then lands, the
    tab moves on at once, saying why (it used to stay on a labelled segment until its lease renewal
    called it lost to someone else), and every segment can still be labelled: the old page shows
    nothing after its close (its preload once became a segment the reloaded tab held, never
    showed and renewed for ever: the run never got its labels)."""
    run = stack.post_run("point", 4, seed=19)
    with stalling_relay(stack.api) as relay:
        config = UiConfig(api=relay.url, run_id=run.id, min_dwell_s=NO_DWELL, min_played=0.0, lease_s=600.0)
        app = LabelingApp(replace(config, release_grace_s=0.5), port=0)
        stack.apps.append(app)
        page = tab(profile(browser), app.labeler_url(stack.new_labeler("reload-in-flight")))
        first = wait_segment(page)
        wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # on screen and preloaded
        relay.stall()
        press(page, "2")
        wait_text(page, "Sending your label")
        page.reload()
        assert wait_segment(page) == first  # not labelled yet: it is still this tab's
        relay.resume()  # the old page's label arrives
        wait_text(page, "Already labelled", timeout_s=30)  # not after a lease renewal (200 s)
        shown = wait_segment(page, first, timeout_s=30)
        labelled = {first}
        while shown not in labelled:
            labelled.add(shown)
            press(page, "1")
            shown = wait_segment(page, shown) if len(labelled) < 4 else shown
        wait_text(page, "Nothing to label right now")
        assert {q: v for q, (v, _) in effective(stack, run.id).items()} == {q: 1 if q == first else 0 for q in labelled}
        wait_until(lambda: stack.trainer.run(run.id).queue.leased == 0)
        assert "Claim lost" not in page.inner_text("body")
        page.context.close()


def test_a_reload_keeps_the_preloaded_segment_too(stack: Stack, browser: Browser) -> None:
    """The reloaded tab took its segment back and preloaded the next one its id held, but only the
    one on screen was taken off the connection the reload replaced: after its grace period that
    connection handed the preload back to the pool, where another labeler took it, and the tab's
    label on it was refused ("its claim ran out")."""
    run = stack.post_run("point", 4, seed=23)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0, release_grace_s=3.0)  # past the new preload
    page = tab(profile(browser), app.labeler_url(stack.new_labeler("reload-preload")))
    first = wait_segment(page)
    wait_until(lambda: stack.trainer.run(run.id).queue.leased == 2)  # on screen and preloaded
    page.reload()
    assert wait_segment(page) == first
    wait_until(lambda: any(s.state.ahead and not s.closed.is_set() for s in app.sessions.values()))
    wait_until(lambda: all(s.finished for s in app._closing))  # the old connection's grace is over
    assert stack.trainer.run(run.id).queue.leased == 2  # the preload is still this tab's
    press(page, "1")
    second = wait_segment(page, first)
    press(page, "1")
    wait_segment(page, second)
    assert "no longer holds" not in page.inner_text("body")
    assert set(effective(stack, run.id)) == {first, second}
    page.context.close()


def test_another_person_signing_in_after_a_reload_cannot_undo_the_labels_made_here(
    stack: Stack, browser: Browser
) -> None:
    """The tab's labels outlive a reload (U walks back through them), but they were handed to
    whoever signed in after it: an operator's U withdrew the labeler's label."""
    run = stack.post_run("point", 3, seed=29)
    app = stack.ui(run.id, min_dwell_s=NO_DWELL, min_played=0.0)
    page = tab(profile(browser), app.labeler_url(stack.new_labeler("first-here")))
    shown = wait_segment(page)
    press(page, "2")
    wait_until(lambda: len(stack.trainer.label_events(run.id)) == 1)
    page.goto(app.labeler_url(TOKENS["operator"]))  # the same browser tab, another person
    wait_text(page, "this tab was signed in as first-here")
    wait_segment(page, shown)
    press(page, "u")
    wait_text(page, "Nothing to undo")
    assert [e.kind for e in stack.trainer.label_events(run.id)] == ["label"]
    page.context.close()
