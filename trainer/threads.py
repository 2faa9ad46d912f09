"""The trainer's CPU thread policy: a run on a shared machine must hold its share, not collapse.

Measured on a 2-core machine (docs/training.md, REFERENCE_NOTES §5): with one other busy process,
torch's default (one OpenMP thread per core, threads that spin while they wait) made a `cpu`
point run 2–5× slower, while one intra-op thread held its pace. So by default the trainer uses one
intra-op thread on machines with ≤ 4 cores or for small nets (hidden ≤ 256), and a passive
OpenMP wait policy everywhere. OpenMP reads its variables once, when torch first starts its pool,
so `apply_openmp_env` must run before `import torch` (`collie train` does; `collie up` also puts
the variables into the trainer's environment). No torch import here.
"""

from __future__ import annotations

import os

SMALL_NET_HIDDEN = 256  # nets this wide gain nothing from a second intra-op thread (batch 256)
FEW_CORES = 4


def resolve_threads(threads: int, hidden: int, cores: int | None = None) -> int:
    """The intra-op thread count for a run: `threads` when set (> 0), else 1 on ≤ 4 cores or for
    small nets, else every core."""
    if threads > 0:
        return threads
    cores = cores or os.cpu_count() or 1
    return 1 if cores <= FEW_CORES or hidden <= SMALL_NET_HIDDEN else cores


def openmp_env(threads: int) -> dict[str, str]:
    """The OpenMP/MKL variables for `threads` intra-op threads that sleep, not spin, while idle."""
    n = str(threads)
    return {"OMP_NUM_THREADS": n, "MKL_NUM_THREADS": n, "OMP_WAIT_POLICY": "PASSIVE"}


def apply_openmp_env(threads: int) -> None:
    """Set the variables in this process (values the user exported win); a no-op once torch is loaded."""
    for key, value in openmp_env(threads).items():
        os.environ.setdefault(key, value)
