"""A Safety-Gym-style pseudo-lidar: how close the nearest object is in each of n directions.

Bin k covers the egocentric angles [k, k + 1)·2π/n, counted anticlockwise from the heading; its
value is max over the objects in it of exp(−distance) (Safety Gym's default closeness, 1 on top
of the object, 0.22 at 1.5 m), and 0 when the bin is empty. Distances are to object centres.
"""

from __future__ import annotations

import numpy as np


def pseudo_lidar(
    xy: np.ndarray, heading: float, objects: np.ndarray, bins: int = 16, out: np.ndarray | None = None
) -> np.ndarray:
    """(bins,) readings seen from position `xy` (2,) facing `heading` (radians) for objects (m, 2)."""
    out = np.zeros(bins, np.float32) if out is None else out
    out[:] = 0.0
    offset = objects - xy
    angle = (np.arctan2(offset[:, 1], offset[:, 0]) - heading) % (2 * np.pi)
    index = np.minimum((angle / (2 * np.pi) * bins).astype(int), bins - 1)  # guards the 2π rounding edge
    np.maximum.at(out, index, np.exp(-np.hypot(offset[:, 0], offset[:, 1])).astype(out.dtype))
    return out
