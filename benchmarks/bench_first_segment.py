"""make bench-first-segment: how long a new user waits, in `make demo`'s stack (point, north, cpu:
service, trainer and labeling UI, as `collie up` starts them), for the first segment to label,
with one CPU-bound process beside it (as a browser rendering WebGL in software is) and alone —
and where those seconds go, part by part.

Target (issue 11): `first_segment_s` ≤ 45 s with the busy process (it was 886 s with torch's default
threads; 33 s on a quiet machine). Issue 12: `--env ant` times `collie up --env ant --task north`
(target ≤ 10 min; with people labelling it asks first at epoch 240, `people_schedule` in trainer/config.py).

The split comes from the stack's own timeline (OUT/logs/startup.jsonl, collie/startup.py): each
process marks the work it just finished, so a part's seconds are the time since that process's
previous mark (a child's first interval, `python start`, counts from its spawn). The trainer's
epochs before the first feedback session are summed by kind: `collect` (rollouts, including the
epochs before `start_transitions`), `update` (gradient steps), `evaluate`, `checkpoint`. The
critical path: until the trainer's spawn (the service's start), the trainer's parts, the posted
segment until the bench sees it pending. `--browser` also opens the labeler's link in headless
Chromium (tests/chromium.py) as the stack comes up, as a person would, and times the segment on
screen: the UI's claim and first frame (the browser is then the busy process: no busy loop).

JSON (runs/bench/first_segment.json; first_segment_ENV.json for another env, and a suffix for
another preset, --browser and a single run: first_segment_ant-quiet.json for `--env ant --runs
quiet`): first_segment_s (the busy run: beside a busy process, or with --browser beside the
browser tab), first_segment_quiet_s, and per measured run (`busy`, `quiet`) its `parts` (part →
what → wall s) and `parts_cpu` (the same in CPU s), `trainer` and `trainer_cpu` (its epochs summed
by kind), `first_feedback_epoch`, `last_epoch`, `trainer_spawn_s`, `posted_s` (the trainer's post,
since start), `pending_s`, and with --browser, in the busy run only, `tab_open_s` (the page
loaded), `claimed_s` (the tab's claim, seen on the service) and `on_screen_s` (its id on the page,
sent with the first frame). Settings: env, preset, browser, runs.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

from record import record

from collie.client import CollieClient
from collie.schemas import StartupMark
from collie.startup import read_marks

TIMEOUT_S = {"point": 600.0, "ant": 1800.0}  # ant: the first session is at epoch 240 (≈ 9 min quiet)
TRAINER_KINDS = ("collect", "update", "evaluate", "checkpoint")  # summed over the epochs before the first session


def busy() -> None:
    while True:
        pass


class NoSegment(RuntimeError):
    """No segment (in time, or the stack failed); `split` holds the timeline so far."""

    def __init__(self, message: str, split: dict) -> None:
        super().__init__(message)
        self.split = split


def first_segment(tmp: Path, env: str, browser: bool, preset: str = "cpu", timeout_s: float | None = None) -> dict:
    """Seconds from `collie up` to a pending query on the service, and the timeline's split."""
    info = tmp / "info.json"
    cmd = [sys.executable, "-m", "collie.cli", "up", "--env", env, "--task", "north", "--preset", preset]
    cmd += ["--port", "0", "--ui-port", "0", "--out", str(tmp / "stack"), "--info-json", str(info)]
    timeout_s = timeout_s or TIMEOUT_S.get(env, 1800.0)
    t0_wall, start = time.time(), time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        while not info.exists():
            if proc.poll() is not None or time.monotonic() - start > timeout_s:
                raise RuntimeError(f"collie up did not come up (logs in {tmp / 'stack' / 'logs'})")
            time.sleep(0.2)
        meta = json.loads(info.read_text())
        seen: dict[str, float | Exception] = {}

        def watch_queue() -> None:  # in a thread: the browser's start must not delay this reading
            try:
                with CollieClient(meta["api"], meta["tokens"]["operator"]) as client:
                    while (queue := client.run(meta["run_id"]).queue).pending + queue.leased == 0:
                        if proc.poll() is not None or time.monotonic() - start > timeout_s:
                            raise RuntimeError("no segment to label in time")
                        time.sleep(0.2)
                    seen["pending"] = time.monotonic() - start
                    while browser and client.run(meta["run_id"]).queue.leased == 0:  # the tab's claim
                        if proc.poll() is not None or time.monotonic() - start > timeout_s:
                            raise RuntimeError("the tab did not claim the segment in time")
                        time.sleep(0.1)
                    seen["claimed"] = time.monotonic() - start
            except Exception as exc:  # re-raised below, in the bench's thread
                seen["error"] = exc

        watcher = threading.Thread(target=watch_queue, daemon=True)
        watcher.start()
        on_screen = None
        with tab(meta["labeling_ui"] if browser else None) as page:
            tab_open = time.monotonic() - start
            if page is not None:
                from ui.page import wait_segment

                wait_segment(page, timeout_s=max(1.0, timeout_s - (time.monotonic() - start)))
                on_screen = time.monotonic() - start
        while watcher.is_alive():  # in steps: Ctrl-C still reaches this thread
            watcher.join(0.5)
        result = split(read_marks(tmp / "stack" / "logs" / "startup.jsonl"), t0_wall)
        if "error" in seen:
            raise NoSegment(str(seen["error"]), result)
        shown = {"tab_open_s": tab_open, "claimed_s": seen["claimed"], "on_screen_s": on_screen} if browser else {}
        return {**result, "pending_s": seen["pending"], **shown}
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)


class tab:
    """The labeler's link open in headless Chromium (or nothing, for url None)."""

    def __init__(self, url: str | None) -> None:
        self.url, self._stack = url, None

    def __enter__(self):
        if self.url is None:
            return None
        import contextlib

        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        from chromium import chromium
        from ui.page import open_labeler

        self._stack = contextlib.ExitStack()
        return open_labeler(self._stack.enter_context(chromium()), self.url)

    def __exit__(self, *exc: object) -> None:
        if self._stack is not None:
            self._stack.close()


def split(marks: list[StartupMark], t0: float) -> dict:
    """Each process's marks as part → what → seconds (time since that process's previous mark; a
    child's first from its spawn), the trainer's startup summed by kind, and the critical path."""
    parts: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    cpu: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    spawns = [(m.what.removeprefix("spawned "), m.t) for m in marks if m.part == "up" and m.what.startswith("spawned ")]

    def spawned_before(part: str, t: float) -> float:  # a restarted part: its latest spawn before t
        return max((s for p, s in spawns if p == part and s <= t), default=t0)

    last: dict[int, tuple[float, float]] = {}  # pid → its previous mark's wall time and CPU time
    first_session = None
    posted = None
    for m in marks:
        before, cpu_before = last.get(m.pid, (spawned_before(m.part, m.t) if m.part != "up" else t0, 0.0))
        last[m.pid] = m.t, m.cpu
        if m.part == "up" and m.what.startswith("spawned "):
            continue
        what = m.what
        if m.part == "trainer" and m.what in TRAINER_KINDS and m.epoch:
            what = f"epochs: {m.what}"
        parts[m.part][what] += m.t - before
        cpu[m.part][what] += m.cpu - cpu_before
        if m.what == "query selection":
            first_session = m.epoch
        if m.what == "segments posted":
            posted = m.t - t0
    trainer, trainer_cpu = parts.get("trainer", {}), cpu.get("trainer", {})

    def rounded(table: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
        return {p: {w: round(s, 2) for w, s in ws.items()} for p, ws in table.items()}

    return {
        "parts": rounded(parts),
        "parts_cpu": rounded(cpu),
        "trainer": {k: round(trainer.get(f"epochs: {k}", 0.0), 2) for k in TRAINER_KINDS},
        "trainer_cpu": {k: round(trainer_cpu.get(f"epochs: {k}", 0.0), 2) for k in TRAINER_KINDS},
        "first_feedback_epoch": first_session,
        "last_epoch": max((m.epoch or 0 for m in marks if m.part == "trainer"), default=0),
        "trainer_spawn_s": next((round(s - t0, 2) for p, s in spawns if p == "trainer"), None),
        "posted_s": round(posted, 2) if posted is not None else None,
    }


def show(name: str, r: dict) -> None:
    print(f"\n{name}: first segment pending after {r['pending_s']:.1f} s", end="")
    if "on_screen_s" in r:
        print(f"; tab loaded at {r['tab_open_s']:.1f} s, segment claimed at {r['claimed_s']:.1f} s", end="")
    print(f", on screen at {r['on_screen_s']:.1f} s" if "on_screen_s" in r else "")
    print(f"  trainer spawned at {r['trainer_spawn_s']} s; segments posted at {r['posted_s']} s;", end=" ")
    print(f"first feedback epoch {r['first_feedback_epoch']} (last epoch marked {r['last_epoch']})")
    print("  part: total wall s (CPU s) · each piece: wall s (CPU s)")
    for part, whats in r["parts"].items():
        cpu = r["parts_cpu"][part]
        total, total_cpu = sum(whats.values()), sum(cpu.values())
        pieces = " · ".join(f"{w} {s:.2f} ({cpu[w]:.2f})" for w, s in whats.items())
        print(f"  {part:<12} {total:7.2f} s ({total_cpu:.2f})  {pieces}")


def measured(name: str, *args: object, **kwargs: object) -> dict:
    """One stack's figures, printed; a failed or timed-out stack: its split so far, then the error."""
    try:
        r = first_segment(*args, **kwargs)  # type: ignore[arg-type]
    except NoSegment as exc:
        print(f"\n{name}: {exc}; the timeline so far:")
        show(name, {**exc.split, "pending_s": math.nan})
        raise
    show(name, r)
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default="point", help="point (make demo's stack) or ant (issue 12)")
    ap.add_argument("--preset", default="cpu", help="the trainer's preset (smoke: a quick check of the bench)")
    ap.add_argument(
        "--timeout-s", type=float, default=None, help="give up after this long (default: point 600, ant 1800)"
    )
    ap.add_argument("--runs", choices=("both", "quiet", "busy"), default="both", help="which of the two to measure")
    ap.add_argument("--browser", action="store_true", help="open the labeler tab in Chromium, no busy loop")
    args = ap.parse_args()
    figures: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        if args.runs in ("both", "quiet"):
            quiet = measured("quiet machine", Path(tmp) / "quiet", args.env, False, args.preset, args.timeout_s)
            figures.update(first_segment_quiet_s=quiet["pending_s"], quiet=quiet)
        if args.runs in ("both", "busy"):
            loop = None
            if not args.browser:
                loop = mp.Process(target=busy, daemon=True)
                loop.start()
            try:
                beside = "a browser tab" if args.browser else "one busy process"
                shared = measured(
                    f"beside {beside}", Path(tmp) / "busy", args.env, args.browser, args.preset, args.timeout_s
                )
            finally:
                if loop is not None:
                    loop.terminate()
            figures.update(first_segment_s=shared["pending_s"], busy=shared)
    if "first_segment_quiet_s" in figures:
        print(f"\nfirst segment to label, quiet machine: {figures['first_segment_quiet_s']:.1f} s")
    if "first_segment_s" in figures:
        target = "target ≤ 45 s" if args.env == "point" else "target ≤ 600 s"
        print(f"first segment to label, beside it: {figures['first_segment_s']:.1f} s ({target})")
    settings = {"env": args.env, "preset": args.preset, "browser": args.browser, "runs": args.runs}
    record(record_name(args), figures, settings)


def record_name(args: argparse.Namespace) -> str:
    """first_segment[_ENV][-PRESET][-browser][-quiet|-busy]: a partial or browser run never
    overwrites the whole default one's figures."""
    name = "first_segment" if args.env == "point" else f"first_segment_{args.env}"
    name += "" if args.preset == "cpu" else f"-{args.preset}"
    name += "-browser" if args.browser else ""
    return name + ("" if args.runs == "both" else f"-{args.runs}")


if __name__ == "__main__":
    main()
