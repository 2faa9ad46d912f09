"""make bench-guidance: METRA, COLLIE and Oracle on point North, Range, Hole and Hole-North with the
`cpu` preset, 3 seeds each. Runs are independent processes (1 torch thread each, `--jobs` at a
time; the runner of `collie sweep`, trainer/sweep.py); a finished run folder is not rerun. Prints
mean ± population std (ddof 0; `collie report` gives the sample std) of the paper's metrics and the
wall time per run, and writes the same table as markdown next to the runs.

Expected (issue 2): on North, COLLIE's safe ratio ≥ 0.90 while METRA's stays ≤ 0.5; COLLIE's safe
coverage above METRA's on every task; each run ≤ 10 minutes.
JSON (runs/bench/guidance.json): `<task>/<method>` → {<metric>_mean, <metric>_std, seeds} for the
metrics safe_coverage, safe_ratio, composite_coverage, weighted_composite_coverage, wall_s; its
settings: env, preset, tasks, methods, seeds, out and the extra train_flags (`make bench-guidance`
passes the first version's, FIRST_VERSION_FLAGS), so runs with other flags read apart.
"""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

import numpy as np
from record import record
from tqdm import tqdm

from trainer.sweep import grid, run_all

METRICS = ("safe_coverage", "safe_ratio", "composite_coverage", "weighted_composite_coverage", "wall_s")


def table(results: dict[tuple[str, str], list[dict]], tasks: list[str], methods: list[str]) -> str:
    lines = [
        "| task | method | safe coverage | safe ratio | composite cov. | weighted composite cov. | wall s/run |",
        "|---|---|---|---|---|---|---|",
    ]
    for task in tasks:
        for method in methods:
            rs = results.get((task, method), [])
            if not rs:
                continue
            cells = []
            for key in METRICS:
                v = np.array([r[key] for r in rs], dtype=float)
                digits = 2 if key == "safe_ratio" else 0
                cells.append(f"{v.mean():.{digits}f} ± {v.std():.{digits}f}")
            lines.append(f"| {task} | {method} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="point")
    p.add_argument("--tasks", default="north,range,hole,hole_north")
    p.add_argument("--methods", default="metra,collie,oracle")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--jobs", type=int, default=max(1, (os.cpu_count() or 2)))
    p.add_argument("--out", default="runs/bench-guidance")
    p.add_argument("extra", nargs="*", help="extra `collie train` flags after --, e.g. -- --epochs 100")
    a = p.parse_args()
    tasks, methods = a.tasks.split(","), a.methods.split(",")
    root = Path(a.out)
    specs = grid(root, a.env, tasks, methods, list(range(a.seeds)), preset="cpu", flags=tuple(a.extra))
    results: dict[tuple[str, str], list[dict]] = {}
    for spec, summary in tqdm(run_all(specs, a.jobs), total=len(specs), desc="bench-guidance runs", unit="run"):
        if isinstance(summary, Exception):
            raise summary
        results.setdefault((spec.task, spec.method), []).append(summary)
    md = table(results, tasks, methods)
    cmd = "make bench-guidance" + (f"  (extra: {' '.join(a.extra)})" if a.extra else "")
    header = (
        f"env `{a.env}`, preset `cpu`, {a.seeds} seeds, mean ± population std (ddof 0) over seeds; "
        f"{platform.machine()} with {os.cpu_count()} cores, {a.jobs} runs at a time; command: `{cmd}`\n\n"
    )
    (root / "results.md").write_text(header + md + "\n")
    print(header + md)
    north = {m: results.get(("north", m)) for m in ("collie", "metra")}
    if north["collie"] and north["metra"]:
        c = np.mean([r["safe_ratio"] for r in north["collie"]])
        m = np.mean([r["safe_ratio"] for r in north["metra"]])
        print(f"\nNorth safe ratio: COLLIE {c:.2f} (goal ≥ 0.90), METRA {m:.2f} (goal ≤ 0.5)")
    for t in tasks:
        if results.get((t, "collie")) and results.get((t, "metra")):
            c = np.mean([r["safe_coverage"] for r in results[(t, "collie")]])
            m = np.mean([r["safe_coverage"] for r in results[(t, "metra")]])
            print(f"{t}: COLLIE safe coverage {c:.0f} vs METRA {m:.0f} → {'above' if c > m else 'NOT above'}")
    walls = [r["wall_s"] for rs in results.values() for r in rs]
    print(f"wall time per run: max {max(walls):.0f} s (goal ≤ 600 s)")
    figures: dict[str, dict[str, float]] = {}
    for (task, method), runs in results.items():
        cell: dict[str, float] = {"seeds": len(runs)}
        for m in METRICS:
            values = [float(r[m]) for r in runs if m in r]
            cell[f"{m}_mean"], cell[f"{m}_std"] = float(np.mean(values)), float(np.std(values))
        figures[f"{task}/{method}"] = cell
    settings = {"env": a.env, "preset": "cpu", "tasks": tasks, "methods": methods, "seeds": a.seeds, "out": a.out}
    record("guidance", figures, settings | {"train_flags": a.extra})  # what tells one table's runs from another's


if __name__ == "__main__":
    main()
