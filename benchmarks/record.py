"""Every benchmark's final figures as JSON, so runs can be compared: runs/bench/<name>.json.

The file holds the figures a benchmark's docstring names (`figures`), the settings it ran with
where they change the figures (`settings`: flags, counts, sizes), and where and when they were
measured (`meta`: commit, the host's CPU model and core count, load average, torch version and the
CPU kernels it chose when loaded). Each run overwrites it. Strict JSON: a figure that is not finite
(a break-even never reached, a percentile of nothing) is written as null. The CPU matters: the
same 2-core machine has been lent on hosts whose one-thread matmul rate differed by 2×, and
torch's tanh and bmm rank differently against `--fast-ops` from one CPU to another, even with the
same kernels (docs/results.md; trainer/fast_ops.py measures it per host).
"""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

BENCH_DIR = Path(os.environ.get("COLLIE_BENCH_DIR", "runs/bench"))


def _commit() -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return out.stdout.strip() or None


def _cpu_model() -> str | None:
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return platform.processor() or None
    return next((ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")), None)


def _strict(value: Any) -> Any:
    """`value` with every non-finite float as None (JSON has no Infinity or NaN; jq refuses them)."""
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_strict(v) for v in value]
    if isinstance(value, int | float | str | bool) or value is None:
        return None if isinstance(value, float) and not math.isfinite(value) else value
    if hasattr(value, "item"):  # a numpy or torch scalar: its Python value (an int stays an int)
        return _strict(value.item())
    return str(value)  # a Path, a device: as it reads


def record(
    name: str, figures: dict[str, Any], settings: dict[str, Any] | None = None, folder: Path | None = None
) -> Path:
    """Write `figures` (JSON-serialisable) and the `settings` they were measured with to
    runs/bench/<name>.json (or `folder`/<name>.json), and say where."""
    torch = sys.modules.get("torch")
    meta = {
        "bench": name,
        "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "commit": _commit(),
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "load_average_1m": round(os.getloadavg()[0], 2),
        "python": platform.python_version(),
        "torch": getattr(torch, "__version__", None),
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability() if torch is not None else None,
    }
    folder = folder or BENCH_DIR
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.json"
    whole = {"meta": meta, "settings": settings or {}, "figures": figures}
    path.write_text(json.dumps(_strict(whole), indent=2, allow_nan=False))
    print(f"figures written to {path}")
    return path
