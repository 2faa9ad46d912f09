"""Denormal floats flushed to zero during the update (x86 FTZ/DAZ, `torch.set_flush_denormal`).

A dead ReLU unit's gradient is 0, so Adam's moments for its weights decay by β each step into the
denormal range (below 1.2e-38) and stay there: rounding keeps the last few ulps from reaching 0. A
CPU computes on denormals many times slower than on normal floats, so a trained agent's update slows
with every dead unit (docs/results.md). Flushed, those values read as 0, which changes nothing Adam
does at float32's precision, only the bits of archived runs (`--flush-denormal false` keeps them).

Only the update runs flushed: rollouts, MuJoCo and the evaluation keep IEEE arithmetic, so their
observations are bit for bit what they were. The mode belongs to the calling thread, and a thread
pool's workers keep the mode of the moment they started, so the trainer flushes only when the update
runs on one thread (the default on ≤ 4 cores and for small nets, trainer/threads.py): with more,
which workers flush would depend on when the pool started (a resumed run's would differ).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


@contextmanager
def flushing_denormals(on: bool) -> Iterator[None]:
    """Run the block with denormals flushed to zero when `on` (where the CPU supports it)."""
    if not on or not torch.set_flush_denormal(True):  # False: this CPU cannot flush; nothing to undo
        yield
        return
    try:
        yield
    finally:
        torch.set_flush_denormal(False)
