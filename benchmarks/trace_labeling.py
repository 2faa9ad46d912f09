"""python benchmarks/trace_labeling.py: where a label key's wait goes, with three labelers at once
and redundancy 2 (bench_labeling.py's crowd_latency, traced).

Every label key is followed from the keydown in the page to the next segment's id in the DOM:
- queued: the key waited in the tab's worker queue (the worker was still busy after showing the
  segment before: preloading the next, refreshing progress and "my labels");
- label POST: the label's round trip, and inside it the service's handler (services/labels.submit)
  and the time its request waited for the service's event loop;
- claims before the frame: a claim made after the key (a lease check, or no prepared segment ready);
- present: from the label's answer to the next segment's first frame flushed to the browser;
- browser: flushed → the page's DOM shows the new segment id (websocket, viser's client, layout);
and the worker's work after the frame (what a fast next key waits on). Timers wrap our functions
in this process (the service, the UI and the tabs run in it, as in the bench); nothing is mocked.
Prints medians per part; with --json, every key's parts.
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
import tempfile
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_labeling import TIMING_JS, label_rounds
from chromium import chromium
from playwright.sync_api import Page
from ui.page import open_labeler, wait_segment
from ui.stack import Stack, real_stack

from backend.services import labels, leases
from labeling_ui import session as session_module
from labeling_ui.service import ServiceLink

Span = tuple[str, str, float, float]  # (thread, what, start, end) on time.perf_counter
SPANS: list[Span] = []
QUEUED: dict[tuple[str, float], float] = {}  # (worker thread, _submit start) → the key's time (Send.at)
_LOCK = threading.Lock()
CHUNK = 6  # segments per posted session


def timed(owner: Any, name: str, label: str | None = None) -> None:
    """Replace owner.name by a wrapper that records a span per call (in the calling thread)."""
    fn: Callable[..., Any] = getattr(owner, name)

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        if name == "_submit":  # (self, submit, at): when the key was pressed
            QUEUED[(threading.current_thread().name, start)] = args[2]
        try:
            return fn(*args, **kwargs)
        finally:
            with _LOCK:
                SPANS.append((threading.current_thread().name, label or name, start, time.perf_counter()))

    setattr(owner, name, wrapper)


def instrument() -> None:
    for name in ("submit", "claim", "progress", "my_labels", "run", "query"):
        timed(ServiceLink, name, f"link.{name}")
    for name in ("_submit", "_present", "_preload", "_show_progress", "_prepare"):
        timed(session_module.LabelerSession, name)
    timed(labels, "submit", "service.labels.submit")
    timed(leases, "claim", "service.leases.claim")


def keys(found: dict[str, list[float]], pages: list[Page], apps_sessions: list[Any]) -> None:
    """Split every traced key (a _submit span on a worker thread) into its parts."""
    by_thread: dict[str, list[Span]] = defaultdict(list)
    for span in SPANS:
        by_thread[span[0]].append(span)
    service = [s for s in SPANS if s[1].startswith("service.")]
    for session in apps_sessions:
        worker = f"collie-labeler-{session.client.client_id}"
        spans = sorted(by_thread.get(worker, []), key=lambda s: s[2])
        submits = [s for s in spans if s[1] == "_submit"]
        flushed = [t["key_to_frame_s"] for t in session.timings]
        for i, (_, _, start, end) in enumerate(submits):
            inside = [s for s in spans if start <= s[2] and s[3] <= end and s[1] != "_submit"]
            post = next((s for s in inside if s[1] == "link.submit"), None)
            if post is None or i >= len(flushed):
                continue
            present = next((s for s in inside if s[1] == "_present"), None)
            handler = [s for s in service if post[2] <= s[2] and s[3] <= post[3] and s[1].endswith("labels.submit")]
            on_demand = [s for s in inside if s[1] == "link.claim" and s[2] < (present[2] if present else end)]
            found["queued behind the worker"].append(start - QUEUED.get((worker, start), start))
            found["label POST"].append(post[3] - post[2])
            found["  of it: service handler"].append(sum(s[3] - s[2] for s in handler))
            found["claims before the frame"].append(sum(s[3] - s[2] for s in on_demand))
            found["keys with a claim before the frame (share)"].append(float(bool(on_demand)))
            tail = [s for s in inside if present and s[2] >= present[2] and s[1] in ("_preload", "_show_progress")]
            found["after the frame: preload + progress"].append(sum(s[3] - s[2] for s in tail))
            found["_submit start → frame flushed, less POST"].append(
                max(0.0, (present[2] - start if present else 0.0) - (post[3] - post[2]))
            )
            found["key → frame flushed (server share)"].append(flushed[i])
    for page in pages:
        found["in page: key → segment id"].extend(float(x) / 1000 for x in page.evaluate("window.__lat"))


def crowd(stack: Stack, browser: Any, n: int, think_s: float, labelers: int, redundancy: int) -> dict[str, list[float]]:
    wanted = (n + 2) * labelers
    sessions = (wanted + CHUNK - 1) // CHUNK
    run = stack.post_run("ant", 0, seed=13, redundancy=redundancy, n_total=sessions * CHUNK)  # the service's budget
    for session in range(sessions):  # small posts: a busy machine's timeouts
        stack.post_session(run.id, "ant", session, CHUNK, seed=13)
    app = stack.ui(run.id, min_dwell_s=0.05, min_played=0.0)
    pages: list[Page] = [
        open_labeler(browser, app.labeler_url(stack.new_labeler(f"trace-{i}"))) for i in range(labelers)
    ]
    current = [wait_segment(p, timeout_s=60) for p in pages]
    for p in pages:
        p.evaluate(TIMING_JS)
    SPANS.clear()
    label_rounds(pages, current, n, think_s)
    time.sleep(0.5)
    found: dict[str, list[float]] = defaultdict(list)
    keys(found, pages, list(app.sessions.values()))
    for p in pages:
        p.context.close()
    return found


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--labels", type=int, default=20)
    parser.add_argument("--think-s", type=float, default=0.6)
    parser.add_argument("--labelers", type=int, default=3)
    parser.add_argument("--redundancy", type=int, default=2)
    parser.add_argument("--json", type=Path, default=None, help="write every key's parts here")
    args = parser.parse_args()
    instrument()
    with tempfile.TemporaryDirectory() as tmp, real_stack(Path(tmp) / "trace.db") as stack, chromium() as browser:
        found = crowd(stack, browser, args.labels, args.think_s, args.labelers, args.redundancy)
    print(f"\ntrace-labeling · {args.labelers} labelers · redundancy {args.redundancy} · {args.labels} keys each")
    for name, values in found.items():
        if name.endswith("(share)"):
            print(f"  {name:<44} {statistics.mean(values):8.2f}")
            continue
        print(f"  {name:<44} median {1000 * statistics.median(values):8.1f} ms   max {1000 * max(values):8.1f} ms")
    if args.json is not None:
        args.json.write_text(json.dumps(found))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
