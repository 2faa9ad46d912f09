"""make bench-exit: what the end of a `collie train` costs, with and without `collie.cli.entry`'s
`gc.freeze()`. A 2-epoch point `cpu` run, started as `python -m collie.cli` (entry: the heap frozen
after the command) and as `main` alone (Python's shutdown collection walks it), alternating for
`--rounds` rounds; the wall time of each whole process (start to exit), medians.

JSON (runs/bench/exit.json): main_s, entry_s (medians, seconds), saved_s (their difference),
main_all_s, entry_all_s (every round), rounds.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from record import record

RUN = ["train", "--env", "point", "--preset", "cpu", "--epochs", "2", "--start-transitions", "200", "--method", "metra"]
STARTS = {
    "entry": [sys.executable, "-m", "collie.cli"],
    "main": [sys.executable, "-c", "import sys; from collie.cli import main; sys.exit(main())"],
}


def wall_s(start: list[str], out: Path) -> float:
    began = time.perf_counter()
    subprocess.run([*start, *RUN, "--no-progress", "--out", str(out)], check=True, capture_output=True)
    return time.perf_counter() - began


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=3)
    a = p.parse_args()
    walls: dict[str, list[float]] = {name: [] for name in STARTS}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.rounds):
            for name, start in STARTS.items():
                walls[name].append(wall_s(start, Path(tmp) / f"{name}{r}"))
                print(f"round {r + 1}/{a.rounds}: {name} {walls[name][-1]:.2f} s", flush=True)
    main_s, entry_s = float(np.median(walls["main"])), float(np.median(walls["entry"]))
    figures = {
        "main_s": main_s,
        "entry_s": entry_s,
        "saved_s": main_s - entry_s,
        "main_all_s": walls["main"],
        "entry_all_s": walls["entry"],
        "rounds": a.rounds,
    }
    print(
        f"a 2-epoch point collie train, whole process: main {main_s:.2f} s, entry {entry_s:.2f} s "
        f"→ {main_s - entry_s:.2f} s saved at exit"
    )
    record("exit", figures)


if __name__ == "__main__":
    main()
