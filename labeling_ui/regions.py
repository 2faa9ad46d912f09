"""The task's regions on the 3D floor: red edges where bad meets not bad, and a tint of the bad and
good areas, both in world x-y (Task.to_dict() shapes; the tint from the task's own rule)."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from collie.class_colours import PALE, STRONG, to_rgb
from collie.tasks import BAD, GOOD, Task
from labeling_ui.inset import class_map

FLOOR_Z = 0.02  # lines sit this far above the floor so they do not z-fight with the grid
REGION_EXTENT = 60.0  # how far unbounded edges (wedge rays, half-planes) are drawn
EDGE_RGB = {c: to_rgb(colour) for c, colour in STRONG.items()}  # the class colours of every screen
TINT_Z = 0.005  # just above the floor grid, which would hide anything below it
TINT_GRID_Z = 0.012  # our own grid lines over the tint keep the motion cue inside tinted areas
TINT_RGB = {c: to_rgb(PALE[c]) for c in (BAD, GOOD)}  # neutral stays untinted
REACH = 3  # cells either side of a run's end searched for the region edge at a row's top and bottom
REFINE_STEPS = 12  # bisection steps placing a tint edge on the region edge: a cell's width / 1024


def on_floor(xy: np.ndarray, z: float = FLOOR_Z) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([xy, np.full(len(xy), z)])


def densify(points: np.ndarray, step: float = 1.0) -> np.ndarray:
    """The same polyline with a point at least every `step`: screen-thick lines whose segment
    crosses behind the camera are dropped by the browser, so long edges are drawn in short pieces."""
    pieces = [points[:1]]
    for a, b in itertools.pairwise(points):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        pieces.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.vstack(pieces)


def region_outline(region: dict[str, Any]) -> np.ndarray | None:
    """Floor points tracing one region's edge, or None if it has no x-y shape (pitch rules)."""
    kind = region.get("kind")
    if kind in ("disc", "outside_disc"):
        (cx, cy), r = region["centre"], region["radius"]
        t = np.linspace(0.0, 2 * math.pi, 97)
        return on_floor(np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)]))
    if kind == "wedge_north":
        ax, ay = region.get("apex", (0.0, 0.0))
        d = REGION_EXTENT
        return densify(on_floor(np.array([[ax - d, ay + d], [ax, ay], [ax + d, ay + d]])))
    if kind == "polygon":  # closed: back to the first vertex
        vertices = np.asarray(region["vertices"], dtype=np.float64)
        return densify(on_floor(np.vstack([vertices, vertices[:1]])))
    if kind in ("halfplane_left", "halfplane_right"):
        x0 = region.get("x0", 0.0)
        return densify(on_floor(np.array([[x0, -REGION_EXTENT], [x0, REGION_EXTENT]])))
    return None


def edge_rgb(region: dict[str, Any], task: dict[str, Any] | None) -> tuple[int, int, int]:
    """Red for a safety edge (bad on one side), else the colour of the region's class."""
    borders_bad = region["desirability"] == 0 or (task is not None and task.get("background") == 0)
    return EDGE_RGB[BAD] if borders_bad else EDGE_RGB.get(region["desirability"], (0, 0, 0))


def _refine(
    task: Task, cls: int, x_in: np.ndarray, x_out: np.ndarray, y: np.ndarray, fallback: np.ndarray
) -> np.ndarray:
    """Where, between x_in (of class `cls`) and x_out (not), the task's class changes along each row
    y: bisection on the task's own rule, so the tint's edge follows the true region edge instead of
    the grid's cells; `fallback` (the cell edge) where the two ends do not straddle it at that y."""
    inside = task.classify(np.column_stack([x_in, y])) == cls
    outside = task.classify(np.column_stack([x_out, y])) != cls
    lo, hi = x_in.copy(), x_out.copy()
    for _ in range(REFINE_STEPS):
        mid = (lo + hi) / 2
        hit = task.classify(np.column_stack([mid, y])) == cls
        lo, hi = np.where(hit, mid, lo), np.where(hit, hi, mid)
    return np.where(inside & outside, (lo + hi) / 2, fallback)


def tint_meshes(
    task: Task | None, cx: float, cy: float, half: float, cells: int = 120
) -> list[tuple[tuple[int, int, int], np.ndarray, np.ndarray]]:
    """(colour, vertices, faces) of flat opaque meshes covering the bad and good areas of a square
    around (cx, cy): one quad per run of equal cells in a row, its left and right ends moved onto the
    region's edge at the row's bottom and top (so a circle's tint is round, not stepped). Opaque,
    because a translucent tint is depth-sorted against the translucent floor grid and vanishes under
    it from some viewpoints."""
    classes = class_map(task, cx, cy, half, cells)
    edges = np.linspace(-half, half, cells + 1)
    centres = (edges[:-1] + edges[1:]) / 2
    smooth = task is not None and not task.uses_pitch
    meshes = []
    for cls, rgb in TINT_RGB.items():
        quads = []
        for row in range(cells):  # row 0 is the north edge
            inside = np.concatenate([[False], classes[row] == cls, [False]])
            starts = np.flatnonzero(~inside[:-1] & inside[1:])
            stops = np.flatnonzero(inside[:-1] & ~inside[1:])
            y0, y1 = cy + edges[cells - row - 1], cy + edges[cells - row]
            quads += [(a, b, y0, y1) for a, b in zip(starts, stops, strict=True)]
        if not quads:
            continue
        q = np.array(quads)
        a, b = q[:, 0].astype(int), q[:, 1].astype(int)
        left, right = cx + edges[a], cx + edges[b]
        corners_x = np.stack([left, right, right, left], axis=1)  # (bottom-left, bottom-right, top-right, top-left)
        if smooth:
            assert task is not None
            for k, y in ((0, q[:, 2]), (3, q[:, 3])):  # the left ends, at the bottom and the top
                can = a > 0
                inner, outer = np.minimum(a[can] + REACH, b[can] - 1), np.maximum(a[can] - 1 - REACH, 0)
                corners_x[can, k] = _refine(task, cls, cx + centres[inner], cx + centres[outer], y[can], left[can])
            for k, y in ((1, q[:, 2]), (2, q[:, 3])):  # the right ends
                can = b < cells
                inner, outer = np.maximum(b[can] - 1 - REACH, a[can]), np.minimum(b[can] + REACH, cells - 1)
                corners_x[can, k] = _refine(task, cls, cx + centres[inner], cx + centres[outer], y[can], right[can])
        corners_y = np.stack([q[:, 2], q[:, 2], q[:, 3], q[:, 3]], axis=1)
        vertices = on_floor(np.stack([corners_x, corners_y], axis=2).reshape(-1, 2), z=TINT_Z)
        base = 4 * np.arange(len(q))[:, None]
        faces = np.concatenate([base + np.array([0, 1, 2]), base + np.array([0, 2, 3])]).astype(np.uint32)
        meshes.append((rgb, vertices, faces))
    return meshes


def tint_grid(cx: float, cy: float, half: float, spacing: float = 1.0, piece: float = 2.0) -> np.ndarray:
    """(N, 2, 3) lines on whole multiples of `spacing` across the tinted square (the floor grid's
    section lines, redrawn over the tint that hides them)."""
    xs = np.arange(np.ceil((cx - half) / spacing), np.floor((cx + half) / spacing) + 1) * spacing
    ys = np.arange(np.ceil((cy - half) / spacing), np.floor((cy + half) / spacing) + 1) * spacing
    ticks = np.arange(-half, half + piece / 2, piece)  # short pieces, as `densify` explains
    starts, stops = ticks[:-1], ticks[1:]
    pieces = [
        np.stack(
            [
                np.column_stack([np.full_like(starts, x), cy + starts]),
                np.column_stack([np.full_like(stops, x), cy + stops]),
            ],
            axis=1,
        )
        for x in xs
    ]
    pieces += [np.stack([np.column_stack([cx + starts, np.full_like(starts, y)]),
                         np.column_stack([cx + stops, np.full_like(stops, y)])], axis=1) for y in ys]  # fmt: skip
    pairs = np.concatenate(pieces)
    return on_floor(pairs.reshape(-1, 2), z=TINT_GRID_Z).reshape(-1, 2, 3)
