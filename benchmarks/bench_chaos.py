"""Chaos benchmark (issue 13): one oracle-labelled point run under `collie up`, with random
`kill -9` spread over the service, trainer, teacher and labeling UI; `collie up` restarts each as it
does for any crash. Afterwards, from the database and the trainer's checkpoint: kills per part,
labels stored, labels applied, duplicates, lost, sessions re-asked, finished. Goal: 0 lost, 0
duplicated, 0 re-asked, finished.

    python benchmarks/bench_chaos.py                 # ~1000 labels, 100 kills (make bench-chaos)
    python benchmarks/bench_chaos.py --short         # 12 kills on a small run (the test's size)

The oracle labels at a person's pace (--teacher-rate), so that a fast machine does not finish the
run before the kills are done. Kills are spread by progress, not by time: kill i waits until the
run's progress (the mean of its label and epoch fractions, the highest seen so far) passes
0.8·(i+1)/(kills+1), and until the last part killed is back, so every kill lands on a live stack
and the run always moves on between kills.
JSON (chaos.json beside OUT, the stack's folder; default OUT runs/bench/chaos: runs/bench/chaos.json):
kills (part → kills), kills_total, labels_wanted, labels_stored, labels_applied, duplicates, lost,
applied_not_stored, sessions, sessions_re_asked, queries_asked, finished, exit_code, wall_s.
Settings: short, kills, seed, teacher_rate."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch
from record import record

from collie.client import CollieClient
from collie.processes import running

PARTS = ("service", "trainer", "teacher", "labeling_ui")
# The smoke preset stretched to ~1000 labels: 100 sessions of 10, one per epoch, a checkpoint each epoch.
FULL = "--epochs 110 --feedback-every 1 --queries-per-session 10 --total-queries 1000 --candidates 20"
SHORT = "--epochs 14 --feedback-every 1 --queries-per-session 5 --total-queries 50 --candidates 10"
COMMON = "--eval-every 50 --checkpoint-every 1"


def children(out: Path) -> dict[str, int]:
    try:
        return json.loads((out / "children.json").read_text())["children"]
    except (FileNotFoundError, json.JSONDecodeError):
        return {}


def progress(client: CollieClient, run_id: int) -> float | None:
    try:
        run = client.run(run_id)
    except Exception:  # the service is restarting
        return None
    labels = run.n_labels / run.n_total if run.n_total else 1.0
    epochs = (run.epoch or 0) / run.epochs_total if run.epochs_total else 0.0
    return (labels + epochs) / 2


def chaos(out: Path, kills: int, seed: int, up: subprocess.Popen) -> dict[str, int]:
    """Kill random parts of the stack as the run progresses; returns kills per part."""
    rng = np.random.default_rng(seed)
    info = out / "info.json"
    while not info.exists():
        if up.poll() is not None:
            raise RuntimeError(f"collie up exited with {up.returncode} before the stack was up")
        time.sleep(0.2)
    meta = json.loads(info.read_text())
    done = dict.fromkeys(PARTS, 0)
    order = [p for _ in range(kills // len(PARTS) + 1) for p in rng.permutation(PARTS)][:kills]
    best, last_killed = 0.0, None  # (part, pid) of the last kill: wait until it is back
    with CollieClient(meta["api"], meta["tokens"]["operator"], timeout_s=5.0) as client:
        for i, part in enumerate(order):
            while up.poll() is None:
                now = progress(client, meta["run_id"])
                best = max(best, now or 0.0)
                pids = children(out)
                back = last_killed is None or (
                    pids.get(last_killed[0], last_killed[1]) != last_killed[1] and running(pids[last_killed[0]])
                )
                if now is not None and back and best >= 0.8 * (i + 1) / (kills + 1) and best < 1.0:
                    break
                time.sleep(0.1)
            if up.poll() is not None:
                break
            pid = children(out)[part]
            if running(pid):
                os.kill(pid, signal.SIGKILL)
                done[part] += 1
                last_killed = (part, pid)
            time.sleep(float(rng.uniform(0.0, 1.0)))  # not always right at a threshold
    return done


def tally(out: Path, kills: dict[str, int], code: int, wall_s: float) -> dict:
    """What the database and the trainer's checkpoint say after the run."""
    meta = json.loads((out / "info.json").read_text())
    run_id = meta["run_id"]
    with sqlite3.connect(out / "collie.db") as db:
        events = db.execute(
            "SELECT COUNT(*), COUNT(DISTINCT query_pk) FROM label_events WHERE run_id = ? AND kind = 'label'", (run_id,)
        ).fetchone()
        stored = dict(
            db.execute("SELECT query_id, label FROM queries WHERE run_id = ? AND label IS NOT NULL", (run_id,))
        )
        sessions = db.execute(
            "SELECT session, MIN(epoch), COUNT(*) FROM queries WHERE run_id = ? GROUP BY session", (run_id,)
        ).fetchall()
        n_total = db.execute("SELECT n_total FROM runs WHERE id = ?", (run_id,)).fetchone()[0]
    ckpt_path = out / "trainer" / "checkpoint.pt"
    ckpt = torch.load(ckpt_path, weights_only=False) if ckpt_path.exists() else {"labelled": {}, "epoch": 0}
    applied = {qid: seg["label"] for qid, seg in ckpt["labelled"].items()}
    summary_path = out / "trainer" / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    epochs = [epoch for _, epoch, _ in sessions]
    return {
        "kills": kills,
        "kills_total": sum(kills.values()),
        "labels_wanted": n_total,
        "labels_stored": len(stored),
        "labels_applied": len(applied),
        "duplicates": events[0] - events[1],  # label events beyond one per query (one oracle labels)
        "lost": sum(1 for q, v in stored.items() if applied.get(q) != v),  # stored, not applied as stored
        "applied_not_stored": sum(1 for q in applied if q not in stored),
        "sessions": len(sessions),
        "sessions_re_asked": len(epochs) - len(set(epochs)),  # a second session at an epoch already asked
        "queries_asked": sum(n for _, _, n in sessions),
        "finished": code == 0 and summary.get("status") == "finished" and ckpt["epoch"] == summary["config"]["epochs"],
        "exit_code": code,
        "wall_s": round(wall_s, 1),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--short", action="store_true", help="the test's size: 50 labels, 12 kills")
    p.add_argument("--kills", type=int, default=None, help="kill -9 count (default 100, --short 12)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--teacher-rate", type=float, default=None, help="oracle labels per second (default 4, --short 1)")
    p.add_argument("--out", type=Path, default=Path("runs/bench/chaos"), help="the stack's folder (emptied first)")
    p.add_argument("--timeout", type=float, default=3600.0, help="give up after this many seconds")
    args = p.parse_args(argv)
    kills = args.kills if args.kills is not None else (12 if args.short else 100)
    out: Path = args.out
    if out.exists():
        subprocess.run(["rm", "-rf", str(out)], check=True)
    out.mkdir(parents=True)
    cmd = [sys.executable, "-m", "collie.cli", "up", "--env", "point", "--task", "north", "--method", "collie"]
    cmd += ["--preset", "smoke", "--teacher", "oracle", "--seed", str(args.seed), "--port", "0", "--ui-port", "0"]
    cmd += ["--out", str(out), "--info-json", str(out / "info.json"), "--exit-when-done", "--max-restarts", "1000"]
    cmd += ["--teacher-rate", str(args.teacher_rate or (1.0 if args.short else 4.0))]
    cmd += ["--train-args", f"{SHORT if args.short else FULL} {COMMON}"]
    started, done = time.monotonic(), dict.fromkeys(PARTS, 0)
    with open(out / "up.out", "wb") as log:
        up = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        try:
            done = chaos(out, kills, args.seed, up)
            code = up.wait(timeout=max(1.0, args.timeout - (time.monotonic() - started)))
        except subprocess.TimeoutExpired:
            up.send_signal(signal.SIGINT)
            code = up.wait(timeout=60)
        finally:
            if up.poll() is None:
                up.kill()
    result = tally(out, done, code, time.monotonic() - started)
    for key, value in result.items():
        print(f"{key:>20}: {value}")
    settings = {
        "short": args.short,
        "kills": kills,
        "seed": args.seed,
        "teacher_rate": cmd[cmd.index("--teacher-rate") + 1],
    }
    record("chaos", result, settings, folder=out.parent)
    ok = result["finished"] and result["lost"] == 0 and result["duplicates"] == 0 and result["sessions_re_asked"] == 0
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
