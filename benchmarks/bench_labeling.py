"""make bench-labeling: the labeling UI against a real stack (service + UI + headless Chromium).

Measures, in one run:
- scene build: the server-side mjviser build of each env's robot (target ≤ 1 s); each model is
  compiled once per UI process, in the background as the UI starts (its time is printed too);
- next segment's first frame after the label key, in the page: from the keydown event to the DOM
  showing the next segment id, which arrives in the same atomic message batch as that segment's
  first pose (target ≤ 300 ms); also the server's share (key received → first frame flushed);
- replay rate for ant: pose updates the server sends per second while a segment loops at 1× and
  4× (target 30 fps), and the server's work per update against the 33 ms a 30 fps frame allows
  (what holds on a busy machine); the browser's own frame rate is printed too, playing, paused,
  and on viser's empty page (on a machine without a GPU it measures software WebGL and viser's
  page; `bench_browser_ceiling.py` measures what each part of the scene costs a frame there);
- the same key → next segment with three labelers at once and redundancy 2 (target ≤ 200 ms;
  redundancy is a run setting of the service where it exists, else the bench says r = 1);
- UI overhead per label: the median wait above, as a share of the ≈ 3.6 s per label the
  literature reports: a labeler exceeds 1000 labels / h when their own time per label stays
  under 3.6 s minus this wait.

Needs Debian's chromium (`apt-get install -y chromium`) and `pip install playwright`.
JSON (runs/bench/labeling.json): one key per printed row, its name in snake case with the unit
(e.g. `in_page_median_ms`, `three_labelers_in_page_median_ms`, `ant_scene_build_ms`,
`server_1x_fps`, `browser_ant_paused_fps`); `--only-crowd` writes only the
three-labeler rows, to runs/bench/labeling_crowd.json. The `three_labelers_segments_still_*`
rows are a diagnostic: the same crowd with each segment held on its first frame. Settings: the
redundancy the crowd rows used (1 where the service has none), labels, think_s, viewport, and the
Chromium version.
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from playwright.sync_api import Page

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import ui.page
from bench_browser_ceiling import FPS_JS, page_fps
from chromium import chromium
from record import record
from ui.page import open_labeler, wait_segment
from ui.stack import Stack, real_stack

from trainer.envs import ENV_NAMES

HUMAN_S = 3.6  # seconds of human time per label (Christiano et al. 2017)

TIMING_JS = """() => {
  window.__lat = [];
  const sid = () => {
    const p = [...document.querySelectorAll("p")].find((e) => e.textContent.startsWith("Segment "));
    return p ? p.querySelector("code")?.textContent ?? null : null;
  };
  let last = sid();
  document.addEventListener("keydown", () => { window.__keyAt = performance.now(); }, true);
  new MutationObserver(() => {
    const id = sid();
    if (id !== null && id !== last) { last = id; window.__lat.push(performance.now() - window.__keyAt); }
  }).observe(document.body, {subtree: true, childList: true, characterData: true});
}"""


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


FIGURES: dict[str, float] = {}  # every printed row, for runs/bench/labeling.json


def row(name: str, value: float, unit: str, target: str, ratio: float | None = None) -> None:
    FIGURES[re.sub(r"[^a-z0-9]+", "_", f"{name} {unit}".lower()).strip("_")] = value
    ratio_text = f"{ratio:6.2f}×" if ratio is not None else "       "
    print(f"  {name:<44} {value:9.1f} {unit:<8} {ratio_text}  target {target}")


def scene_builds(stack: Stack, browser: object, envs: list[str]) -> dict[str, tuple[float, float, float]]:
    """env → (model compile seconds at UI start, server scene build seconds, page-open-to-segment seconds)."""
    result = {}
    compiled: dict[str, float] = {}  # the first UI's warm-up compiles every model (later ones hit its cache)
    for env in envs:
        run = stack.post_run(env, 1)
        app = stack.ui(run.id)
        deadline = time.monotonic() + 60
        while env not in app.compile_s and time.monotonic() < deadline:  # a labeler comes after start-up
            time.sleep(0.05)
        compiled = compiled or dict(app.compile_s)
        start = time.perf_counter()
        page = open_labeler(browser, app.labeler_url(stack.new_labeler(f"build-{env}")))  # type: ignore[arg-type]
        wait_segment(page, timeout_s=60)
        shown = time.perf_counter() - start
        session = next(iter(app.sessions.values()))
        result[env] = (compiled.get(env, float("nan")), session.scene.build_s, shown)
        page.context.close()
    return result


def label_latency(stack: Stack, browser: object, n: int, think_s: float) -> tuple[list[float], list[float]]:
    """Label n ant segments by key: (in-page key → next segment ms, server key → first frame ms)."""
    run = stack.post_run("ant", n + 1, seed=11)
    app = stack.ui(run.id, min_dwell_s=0.05, min_played=0.0)
    page: Page = open_labeler(browser, app.labeler_url(stack.new_labeler("latency")))  # type: ignore[arg-type]
    current = wait_segment(page, timeout_s=60)
    page.evaluate(TIMING_JS)
    for i in range(n):
        time.sleep(think_s)
        page.keyboard.press("12"[i % 2])  # north: good is not a label
        current = wait_segment(page, current, timeout_s=30)
    time.sleep(0.2)
    in_page = [float(x) for x in page.evaluate("window.__lat")]
    session = next(iter(app.sessions.values()))
    server = [1000 * float(t["key_to_frame_s"]) for t in session.timings.snapshot()]
    page.context.close()
    return in_page, server


def label_rounds(pages: list[Page], current: list[str], n: int, think_s: float) -> None:
    """`n` rounds in which every labeler presses a label key in the same moment, then each page
    waits for its next segment (`current` holds the segment ids on screen, updated in place)."""
    for i in range(n):
        time.sleep(think_s / len(pages))
        for k, p in enumerate(pages):
            p.keyboard.press("12"[(i + k) % 2])
        for k, p in enumerate(pages):
            current[k] = wait_segment(p, current[k], timeout_s=30)


def crowd_latency(
    stack: Stack,
    browser: object,
    n: int,
    think_s: float,
    labelers: int = 3,
    redundancy: int = 2,
    playing: bool = True,
) -> tuple[list[float], int]:
    """`labelers` people labelling one ant run at once (each in their own browser context; each
    round their keys are pressed in the same moment), each query wanted `redundancy` times:
    in-page key → next segment ms over every labeler, and the redundancy actually used (1 where
    the service has no such setting). `playing=False` (a diagnostic, not what labelers get):
    every segment stays on its first frame, so the pages draw once per segment instead of at
    every replay tick, which separates the browsers' drawing from the rest of the path."""
    try:
        run = stack.post_run("ant", n * labelers + labelers, seed=13, redundancy=redundancy)
    except ValueError:
        redundancy = 1
        run = stack.post_run("ant", n * labelers + labelers, seed=13)
    app = stack.ui(run.id, min_dwell_s=0.05, min_played=0.0)
    pages: list[Page] = [
        open_labeler(browser, app.labeler_url(stack.new_labeler(f"{'crowd' if playing else 'still'}-{i}")))  # type: ignore[arg-type]
        for i in range(labelers)
    ]
    current = [wait_segment(p, timeout_s=60) for p in pages]
    if not playing:
        for session in app.sessions.values():
            session.player.autoplay = False
            session.player.pause()
    for p in pages:
        p.evaluate(TIMING_JS)
    label_rounds(pages, current, n, think_s)
    time.sleep(0.2)
    found = [float(x) for p in pages for x in p.evaluate("window.__lat")]
    for p in pages:
        p.context.close()
    return found, redundancy


def replay_rates(stack: Stack, browser: object, seconds: float) -> dict[str, float]:
    run = stack.post_run("ant", 1, seed=12)
    app = stack.ui(run.id)
    page: Page = open_labeler(browser, app.labeler_url(stack.new_labeler("fps")))  # type: ignore[arg-type]
    wait_segment(page, timeout_s=60)
    session = next(iter(app.sessions.values()))
    rates = {}
    for speed in (1.0, 4.0):
        session.set_speed(speed)
        ticks, work, start = session.player.ticks, session.player.tick_work_s, time.perf_counter()
        browser_fps = float(page.evaluate(FPS_JS, seconds * 1000))
        n = session.player.ticks - ticks
        rates[f"server {speed:g}x"] = n / (time.perf_counter() - start)
        rates[f"server work per update {speed:g}x (ms)"] = 1000 * (session.player.tick_work_s - work) / max(n, 1)
        rates[f"browser {speed:g}x"] = browser_fps
    session.toggle_play()  # paused: the same scene, no pose updates
    rates["browser, ant paused"] = float(page.evaluate(FPS_JS, seconds * 1000))
    page.context.close()
    # viser's page with nothing of ours and nothing sent: what drawing alone allows in this browser
    rates["browser, empty viser scene"] = page_fps(browser, 0, 0, 30.0, seconds, ui.page.VIEWPORT)
    return rates


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--labels", type=int, default=20, help="labels to time")
    parser.add_argument("--think-s", type=float, default=0.6, help="pause before each key (a fast labeler)")
    parser.add_argument("--fps-s", type=float, default=3.0, help="seconds to count replay frames")
    parser.add_argument("--viewport", default="1280x800")
    parser.add_argument("--only-crowd", action="store_true", help="only the three-labeler rows (playing and still)")
    args = parser.parse_args()
    width, height = (int(v) for v in args.viewport.split("x"))
    ui.page.VIEWPORT = {"width": width, "height": height}

    with tempfile.TemporaryDirectory() as tmp, real_stack(Path(tmp) / "bench.db") as stack, chromium() as browser:
        everything = not args.only_crowd
        builds = scene_builds(stack, browser, list(ENV_NAMES)) if everything else {}
        in_page, server = label_latency(stack, browser, args.labels, args.think_s) if everything else ([], [])
        crowd, redundancy = crowd_latency(stack, browser, args.labels, args.think_s)
        still, _ = crowd_latency(stack, browser, args.labels, args.think_s, playing=False)
        rates = replay_rates(stack, browser, args.fps_s) if everything else {}
        renderer = browser.version

    print(f"\nbench-labeling · chromium {renderer} · viewport {args.viewport} · {args.labels} labels")
    if everything:
        print("model compile (once, as the UI starts), scene build (mjviser → viser), page open → segment shown:")
        for env, (compile_s, build_s, shown_s) in builds.items():
            row(f"{env} model compile at UI start", 1000 * compile_s, "ms", "(info)")
            row(f"{env} scene build", 1000 * build_s, "ms", "≤ 1000 ms", build_s / 1.0)
            row(f"{env} page open → segment on screen", 1000 * shown_s, "ms", "(info)")
        print("next segment's first frame after the label key (ant):")
        row("in page, median", pct(in_page, 50), "ms", "≤ 300 ms", pct(in_page, 50) / 300)
        row("in page, p95", pct(in_page, 95), "ms", "≤ 300 ms", pct(in_page, 95) / 300)
        row("server share (key → frame flushed), median", pct(server, 50), "ms", "(info)")
    print(f"the same with three labelers at once, redundancy {redundancy} (ant):")
    row("three labelers, in page, median", pct(crowd, 50), "ms", "≤ 200 ms", pct(crowd, 50) / 200)
    row("three labelers, in page, p95", pct(crowd, 95), "ms", "(info)")
    row("three labelers, segments still, median", pct(still, 50), "ms", "(diagnostic)", pct(still, 50) / 200)
    row("three labelers, segments still, p95", pct(still, 95), "ms", "(info)")
    print("  (still: each page draws once per segment, not per replay tick; labelers get the playing rows)")
    if everything:
        print("replay rate for ant (pose updates per second):")
        for name, rate in rates.items():
            if "work" in name:
                row(name.removesuffix(" (ms)"), rate, "ms", "≤ 33 ms", rate / (1000 / 30))
            elif name.startswith("server"):
                row(name, rate, "fps", "30 fps", rate / 30)
            else:
                row(name, rate, "fps", "≥ 25 fps (software WebGL here)" if name == "browser 1x" else "(info)")
        print("  (paused, viser draws nothing: not a drawing rate; make bench-browser-ceiling: what each part costs)")
        wait_s = statistics.median(in_page) / 1000 if in_page else float("nan")
        print("UI overhead per label:")
        wait_ms = 1000 * wait_s
        row("wait per label (median key → next segment)", wait_ms, "ms", f"small vs {HUMAN_S} s", wait_s / HUMAN_S)
        row("own time per label that still makes 1000 / h", HUMAN_S - wait_s, "s", "(info)")
    settings = {"redundancy": redundancy, "labels": args.labels, "think_s": args.think_s, "viewport": args.viewport}
    record("labeling" if everything else "labeling_crowd", FIGURES, settings | {"chromium": renderer})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
