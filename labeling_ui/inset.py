"""The top-down 2D inset: the task's regions (painted from the task's own rule, so the picture and
the labels can never disagree), the trajectory's earlier path, and the segment, north up."""

from __future__ import annotations

import itertools

import numpy as np

from collie.class_colours import PALE, to_rgb
from collie.tasks import Task
from labeling_ui.colours import EARLIER_RGB, TO_COME_RGB

SIZE = 240  # pixels, square
CLASS_RGB = {c: to_rgb(colour) for c, colour in PALE.items()}  # as the dashboard's map
NO_RULE_RGB = (244, 245, 247)  # the background of a run without a rule
AXIS_RGB = (200, 200, 205)
SEGMENT_RGB = TO_COME_RGB  # the 3D view's colour of the segment (colours.py)
START_RGB = (30, 30, 30)  # a dark dot where the segment starts, a ring where it ends: the inset has
END_RGB = (255, 255, 255)  # no playhead, and a pink end dot read as "the robot is here" (pink: played, in 3D)
MIN_HALF_WIDTH = 4.0  # world units; a short segment still shows its surroundings


def view_box(*paths: np.ndarray | None) -> tuple[float, float, float]:
    """(centre x, centre y, half width) of a square holding the paths and the origin."""
    points = np.vstack([np.zeros((1, 2)), *[np.asarray(p, float).reshape(-1, 2) for p in paths if p is not None]])
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2
    half = max(float((hi - lo).max()) / 2 * 1.15, MIN_HALF_WIDTH)
    return float(centre[0]), float(centre[1]), half


def pixel_centres(cx: float, cy: float, half: float, size: int) -> np.ndarray:
    """(size*size, 2) world x-y of every pixel of a square view, row-major, row 0 at the top (north)."""
    span = (np.arange(size) + 0.5) / size * 2 - 1
    gx, gy = np.meshgrid(cx + span * half, cy - span * half)
    return np.column_stack([gx.ravel(), gy.ravel()])


def class_map(task: Task | None, cx: float, cy: float, half: float, size: int) -> np.ndarray:
    """(size, size) task class of each pixel (the background where the rule needs pitch)."""
    classes = np.full(size * size, 1 if task is None else task.background, np.int8)
    if task is not None and not task.uses_pitch:
        classes = task.classify(pixel_centres(cx, cy, half, size))
    return classes.reshape(size, size)


class Canvas:
    """World x-y → pixel rows/columns of a SIZE×SIZE image."""

    def __init__(self, cx: float, cy: float, half: float) -> None:
        self.cx, self.cy, self.half = cx, cy, half
        self.image = np.zeros((SIZE, SIZE, 3), np.uint8)

    def to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world → (N, 2) float (column, row)."""
        col = (xy[:, 0] - self.cx) / self.half * SIZE / 2 + SIZE / 2
        row = (self.cy - xy[:, 1]) / self.half * SIZE / 2 + SIZE / 2
        return np.column_stack([col, row])

    def dots(self, pixels: np.ndarray, rgb: tuple[int, int, int], radius: float) -> None:
        r = int(np.ceil(radius))
        offsets = np.array(
            [(dc, dr) for dc in range(-r, r + 1) for dr in range(-r, r + 1) if dc * dc + dr * dr <= radius**2]
        )
        spots = (np.round(pixels)[:, None, :] + offsets[None, :, :]).reshape(-1, 2).astype(int)
        inside = (spots >= 0).all(axis=1) & (spots < SIZE).all(axis=1)
        spots = spots[inside]
        self.image[spots[:, 1], spots[:, 0]] = rgb

    def path(self, xy: np.ndarray, rgb: tuple[int, int, int], radius: float) -> None:
        """A polyline, drawn as dots every half pixel along each piece."""
        pixels = self.to_pixels(np.asarray(xy, float).reshape(-1, 2))
        if len(pixels) == 1:
            self.dots(pixels, rgb, radius)
            return
        pieces = []
        for a, b in itertools.pairwise(pixels):
            n = max(2, int(np.ceil(np.linalg.norm(b - a) * 2)))
            pieces.append(a + (b - a) * np.linspace(0, 1, n)[:, None])
        self.dots(np.vstack(pieces), rgb, radius)


def inset_caption(segment_xy: np.ndarray, earlier_xy: np.ndarray | None) -> str:
    """The inset's scale and where the segment lies, in words: with only an instruction ("keep away
    from the east side") there is no tinted area to judge by, and the inset rescales per segment."""
    half = view_box(segment_xy, earlier_xy)[2]
    xy = np.asarray(segment_xy, float).reshape(-1, 2)
    (x0, y0), (x1, y1) = xy[0], xy[-1]
    return (
        f"{2 * half:.3g} units across · the segment runs from ({x0:+.2f}, {y0:+.2f}) to ({x1:+.2f}, {y1:+.2f}): "
        "x east, y north of the origin (where the grey lines cross; episodes start near it)"
    )


def render_inset(task: Task | None, segment_xy: np.ndarray, earlier_xy: np.ndarray | None) -> np.ndarray:
    """(SIZE, SIZE, 3) uint8 picture of the regions, the earlier path and the segment."""
    canvas = Canvas(*view_box(segment_xy, earlier_xy))
    if task is None:  # only an instruction: no class anywhere, so no shade that would suggest one
        canvas.image[:] = NO_RULE_RGB
    else:
        palette = np.array([CLASS_RGB[c] for c in range(3)], np.uint8)
        canvas.image[:] = palette[class_map(task, canvas.cx, canvas.cy, canvas.half, SIZE)]
    # the axes through the origin, for orientation
    canvas.path(np.array([[canvas.cx - 2 * canvas.half, 0.0], [canvas.cx + 2 * canvas.half, 0.0]]), AXIS_RGB, 0.5)
    canvas.path(np.array([[0.0, canvas.cy - 2 * canvas.half], [0.0, canvas.cy + 2 * canvas.half]]), AXIS_RGB, 0.5)
    if earlier_xy is not None and len(earlier_xy):
        canvas.path(earlier_xy, EARLIER_RGB, 1.0)
    canvas.path(segment_xy, SEGMENT_RGB, 1.8)
    pixels = canvas.to_pixels(np.asarray(segment_xy, float).reshape(-1, 2))
    canvas.dots(pixels[:1], START_RGB, 3.0)
    canvas.dots(pixels[-1:], START_RGB, 4.0)
    canvas.dots(pixels[-1:], END_RGB, 2.2)
    return canvas.image
