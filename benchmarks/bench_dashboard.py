"""The operators' dashboard in Debian's Chromium against a `collie serve` process (`make bench-dashboard`).

Measured:
- a trainer post → the page: the time from just before the trainer's POST (metrics, or rollouts of
  48 skills × 101 points with w(s)) until the page has drawn it (the plot's `data-rendered-at`,
  stamped when Plotly finished), p50 and max over the posts. Target ≤ 1 s.
- loading a run with 10 000 evaluations of metrics (25 values each) and its latest rollouts, in a
  fresh browser context (nothing cached): navigation start → curves and map drawn. Target ≤ 1 s.
  Beside it, in the same run: the service's answer for that page (thinned history) against the
  plain /metrics?limit=10000 a page without thinning would have to read.
Bounded: fixed counts; everything on 127.0.0.1. Prints figures and ratios to the targets.
JSON (runs/bench/dashboard.json): live_p50_ms_<kind>, live_max_ms_<kind> (kind: metrics, rollouts),
cold_load_median_ms, cold_load_max_ms, page_answer_ms, page_answer_bytes, full_answer_ms, full_answer_bytes.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from backend.db import Database
from backend.services import telemetry
from collie.client import CollieClient
from collie.schemas import EnvDims, MetricsIn, RunCreate
from trainer.feedback.http_reporter import rollouts_of
from trainer.telemetry import RolloutsReport

TOKENS = {
    "operator": "bench-operator-0123456789",
    "trainer": "bench-trainer-0123456789",
    "labeler": "bench-labeler-0123456789",
}
TARGET_MS = 1000.0
POSTS = 10
EPOCHS = 10_000
KEYS = (
    "safe_coverage",
    "safe_ratio",
    "composite_coverage",
    "weighted_composite_coverage",
    "n_bins",
    "n_bad_bins",
    "n_neutral_bins",
    "n_good_bins",
    "n_states",
    "n_labels",
    "lambda",
    "alpha",
    "beta",
    "wall_s",
    "qf_loss",
    "policy_loss",
    "q",
    "entropy",
    "phi_loss",
    "lambda_loss",
    "alpha_loss",
    "reward",
    "w_mean",
    "env_steps",
    "n_labelled_states[0]",
)


def serve(folder: Path) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, **{f"COLLIE_{r.upper()}_TOKEN": t for r, t in TOKENS.items()}}
    tokens = folder / "tokens.json"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "collie.cli",
            "serve",
            "--port",
            "0",
            "--db",
            str(folder / "c.db"),
            "--tokens-json",
            str(tokens),
        ],
        env=env,
        stdout=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 60
    while not tokens.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError("the service did not start")
        time.sleep(0.05)
    return proc, json.loads(tokens.read_text())["api"]


def rollouts(epoch: int, rng: np.random.Generator) -> RolloutsReport:
    """What Trainer.evaluate reports: 48 skills, 201 steps thinned to 101 points, w(s) alike, and
    Ant's 15-value qpos at each point (for the watch mode; stored in the same row the page reads)."""
    steps = rng.normal(size=(48, 101, 2)).cumsum(axis=1) * 0.3
    qpos = np.concatenate([steps, rng.normal(size=(48, 101, 13))], axis=2)
    return RolloutsReport(
        epoch, skills=rng.normal(size=(48, 2)), xy=steps, stride=2, qpos=qpos, w=rng.uniform(0, 2, size=(48, 101))
    )


def new_run(trainer: CollieClient) -> int:
    dims = EnvDims(obs_dim=29, nq=15, nv=14, horizon=20, skill_dim=2)
    spec = RunCreate(
        env="ant",
        task="range_north",
        method="collie",
        config={"preset": "paper"},
        dims=dims,
        n_total=100,
        epochs_total=EPOCHS,
    )
    return trainer.create_run(spec).id


def fill(db_url: str, run_id: int, rng: np.random.Generator) -> None:
    db = Database(db_url)
    with db.write() as conn:
        for epoch in range(EPOCHS):
            values = {k: float(v) for k, v in zip(KEYS, rng.normal(size=len(KEYS)), strict=True)}
            telemetry.post_metrics(conn, run_id, MetricsIn(epoch=epoch, values=values))
    db.dispose()


def rendered_at(page, selector: str, attribute: str, value: str) -> float:
    page.wait_for_function(
        f"document.querySelector('{selector}').dataset.{attribute} === '{value}'", timeout=30_000, polling="raf"
    )
    return float(page.evaluate(f"Number(document.querySelector('{selector}').dataset.renderedAt)"))


def live_latency(browser, api: str, trainer: CollieClient, run_id: int, rng: np.random.Generator) -> dict:
    page = browser.new_page(bypass_csp=True, viewport={"width": 1400, "height": 1400})
    page.goto(f"{api}/?token={TOKENS['operator']}#run={run_id}")
    page.wait_for_function("document.querySelector('#map').dataset.renderedAt", timeout=60_000)
    times: dict[str, list[float]] = {"metrics": [], "rollouts": []}
    for i in range(POSTS):
        epoch = EPOCHS + i
        time.sleep(0.5)
        start = time.time() * 1000
        trainer.post_metrics(run_id, MetricsIn(epoch=epoch, values={"safe_coverage": float(i), "safe_ratio": 0.5}))
        times["metrics"].append(rendered_at(page, "#curves", "lastEpoch", str(epoch)) - start)
        body = rollouts_of(rollouts(epoch, rng))
        time.sleep(0.5)
        start = time.time() * 1000
        trainer.post_rollouts(run_id, body)
        times["rollouts"].append(rendered_at(page, "#map", "epoch", str(epoch)) - start)
    page.close()
    return times


def cold_load(browser, api: str, run_id: int) -> list[float]:
    loads = []
    for _ in range(5):
        context = browser.new_context(bypass_csp=True, viewport={"width": 1400, "height": 1400})
        page = context.new_page()
        page.goto(f"{api}/?token={TOKENS['operator']}#run={run_id}")
        page.wait_for_function(
            "document.querySelector('#curves').dataset.points && document.querySelector('#map').dataset.renderedAt",
            timeout=60_000,
        )
        loads.append(
            page.evaluate(
                "Math.max(document.querySelector('#curves').dataset.renderedAt, "
                "document.querySelector('#map').dataset.renderedAt) - performance.timeOrigin"
            )
        )
        context.close()
    return loads


def answer(api: str, path: str) -> tuple[float, int]:
    """Median seconds and bytes of a GET (5 tries)."""
    spent, size = [], 0
    with httpx.Client(headers={"Authorization": f"Bearer {TOKENS['operator']}"}, timeout=60) as client:
        for _ in range(5):
            start = time.perf_counter()
            size = len(client.get(f"{api}/api/{path}").content)
            spent.append(time.perf_counter() - start)
    return statistics.median(spent), size


def main() -> int:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from chromium import chromium
    from record import record

    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        proc, api = serve(Path(tmp))
        try:
            with CollieClient(api, TOKENS["trainer"]) as trainer, chromium() as browser:
                run_id = new_run(trainer)
                fill(f"sqlite:///{Path(tmp) / 'c.db'}", run_id, rng)
                trainer.post_rollouts(run_id, rollouts_of(rollouts(EPOCHS - 1, rng)))
                loads = cold_load(browser, api, run_id)
                live = live_latency(browser, api, trainer, run_id, rng)
            page_s, page_bytes = answer(api, f"dashboard/runs/{run_id}?max_points=500")  # as the page asks
            full_s, full_bytes = answer(api, f"runs/{run_id}/metrics?limit=10000")
        finally:
            proc.terminate()
            proc.wait(10)
    print(f"dashboard benchmark (load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    for kind, ms in live.items():
        p50, worst = statistics.median(ms), max(ms)
        print(
            f"  trainer post → page drawn, {kind:8s}: p50 {p50:6.0f} ms, max {worst:6.0f} ms over {len(ms)} posts "
            f"(target ≤ {TARGET_MS:.0f} ms: p50 at {p50 / TARGET_MS:.2f}×, max at {worst / TARGET_MS:.2f}× of it)"
        )
    load = statistics.median(loads)
    print(
        f"  {EPOCHS} evaluations, cold page load → curves and map drawn: median {load:.0f} ms, "
        f"max {max(loads):.0f} ms over {len(loads)} loads (target ≤ {TARGET_MS:.0f} ms: {load / TARGET_MS:.2f}×)"
    )
    print(f"    each load (ms): {', '.join(f'{x:.0f}' for x in loads)}")
    print(
        f"  the run page's answer: {page_bytes / 1e3:.0f} kB in {page_s * 1000:.0f} ms; all {EPOCHS} rows "
        f"(/metrics?limit=10000): {full_bytes / 1e6:.1f} MB in {full_s * 1000:.0f} ms "
        f"→ {full_bytes / page_bytes:.0f}× fewer bytes, {full_s / page_s:.1f}× faster"
    )
    figures = {f"live_p50_ms_{k}": statistics.median(ms) for k, ms in live.items()}
    figures |= {f"live_max_ms_{k}": max(ms) for k, ms in live.items()}
    record(
        "dashboard",
        figures
        | {
            "cold_load_median_ms": load,
            "cold_load_max_ms": max(loads),
            "page_answer_ms": 1000 * page_s,
            "page_answer_bytes": page_bytes,
            "full_answer_ms": 1000 * full_s,
            "full_answer_bytes": full_bytes,
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
