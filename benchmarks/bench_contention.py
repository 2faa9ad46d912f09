"""make bench-contention: does a trainer hold its share of a busy machine? A `cpu`-preset point run
(`collie train`, the defaults of trainer/threads.py) alone, then beside one CPU-bound process (a
busy loop), interleaved for `--rounds` rounds; the figure is the ratio of the epoch rates.

Goal: `ratio` ≥ 0.8 (one busy process takes one of 2 cores; the default of 2 spinning OpenMP
threads fell to ≈ 0.43). `--train-args "--threads 2"` measures another setting the same way.
JSON (runs/bench/contention.json): alone_rate, shared_rate (epochs/s, medians of the trainer's own
wall time, which excludes start-up), ratio, epochs, rounds, train_args.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from record import record


def epoch_rate(out: Path, epochs: int, train_args: list[str]) -> float:
    cmd = [sys.executable, "-m", "collie.cli", "train", "--env", "point", "--preset", "cpu", "--no-progress"]
    cmd += ["--epochs", str(epochs), "--start-transitions", "1600", "--out", str(out), *train_args]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return epochs / json.loads((out / "summary.json").read_text())["wall_s"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--epochs", type=int, default=20)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--train-args", default="", help='extra `collie train` flags, e.g. "--threads 2"')
    a = p.parse_args()
    extra = a.train_args.split()
    alone, shared = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.rounds):
            alone.append(epoch_rate(Path(tmp) / f"alone{r}", a.epochs, extra))
            busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
            try:
                shared.append(epoch_rate(Path(tmp) / f"shared{r}", a.epochs, extra))
            finally:
                busy.kill()
                busy.wait()
    figures = {
        "alone_rate": float(np.median(alone)),
        "shared_rate": float(np.median(shared)),
        "epochs": a.epochs,
        "rounds": a.rounds,
        "train_args": a.train_args,
    }
    figures["ratio"] = figures["shared_rate"] / figures["alone_rate"]
    print(
        f"point cpu, {a.epochs} epochs, {a.rounds} rounds{' · ' + a.train_args if a.train_args else ''}: "
        f"alone {figures['alone_rate']:.2f} epochs/s, beside a busy process {figures['shared_rate']:.2f} epochs/s "
        f"→ ratio {figures['ratio']:.2f} (goal ≥ 0.8)"
    )
    record("contention", figures)


if __name__ == "__main__":
    main()
