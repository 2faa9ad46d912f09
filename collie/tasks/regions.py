"""Drawable shapes that make up a task's rule, each with a signed distance to its own edge.

A task paints its regions in order over a background class (later regions win). The signed
distance (negative inside, zero on the edge, positive outside) gives membership and boundary
distance from one formula per shape. Edge convention: a region painted BAD is open (its edge is
not bad) and any other region is closed (its edge belongs to it), so points exactly on a safety
boundary are safe and y = |x| counts as y ≥ |x|, as the paper's inequalities say.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np

from collie.tasks.classes import BAD, CLASSES


@dataclass(frozen=True, kw_only=True)
class Region(abc.ABC):
    """A shape whose inside has class `desirability`."""

    desirability: int

    KIND: ClassVar[str] = ""  # the name UIs switch on when drawing
    uses_pitch: ClassVar[bool] = False  # membership depends on pitch, not position

    def __post_init__(self) -> None:
        if self.desirability not in CLASSES:
            raise ValueError(f"desirability must be one of {CLASSES}, got {self.desirability!r}")

    @property
    def kind(self) -> str:
        return self.KIND

    @abc.abstractmethod
    def signed_distance(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        """(N,) signed distance to the edge: < 0 inside, 0 on the edge, > 0 outside."""

    @abc.abstractmethod
    def params(self) -> dict[str, Any]:
        """Geometry as JSON-ready values."""

    def contains(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        sd = self.signed_distance(xy, pitch)
        # Bad regions are open so that every safety boundary belongs to the safe side.
        return sd < 0 if self.desirability == BAD else sd <= 0

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "desirability": self.desirability, **self.params()}


def _xy_pair(point: tuple[float, float]) -> list[float]:
    return [float(point[0]), float(point[1])]


@dataclass(frozen=True)
class Disc(Region):
    """Inside: distance to `centre` below (or, if not bad, up to) `radius`."""

    centre: tuple[float, float]
    radius: float
    KIND: ClassVar[str] = "disc"

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.radius > 0:
            raise ValueError(f"radius must be positive, got {self.radius}")

    def _centre_distance(self, xy: np.ndarray) -> np.ndarray:
        return np.hypot(xy[:, 0] - self.centre[0], xy[:, 1] - self.centre[1])

    def signed_distance(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        return self._centre_distance(xy) - self.radius

    def params(self) -> dict[str, Any]:
        return {"centre": _xy_pair(self.centre), "radius": float(self.radius)}


@dataclass(frozen=True)
class OutsideDisc(Disc):
    """The complement of a disc: distance to `centre` above (or, if not bad, from) `radius`."""

    KIND: ClassVar[str] = "outside_disc"

    def signed_distance(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        return self.radius - self._centre_distance(xy)


@dataclass(frozen=True)
class WedgeNorth(Region):
    """Inside: y − apex_y ≥ |x − apex_x|, the 90° wedge opening north from `apex`."""

    apex: tuple[float, float] = (0.0, 0.0)
    KIND: ClassVar[str] = "wedge_north"

    def signed_distance(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        ax = np.abs(xy[:, 0] - self.apex[0])  # fold onto the right-hand edge ray by symmetry
        y = xy[:, 1] - self.apex[1]
        margin = y - ax  # exact sign for points on the edge
        along = ax + y  # > 0: the nearest edge point lies on the ray, else at the apex
        outside = np.where(along >= 0, -margin / math.sqrt(2), np.hypot(ax, y))
        return np.where(margin >= 0, -margin / math.sqrt(2), outside)

    def params(self) -> dict[str, Any]:
        return {"apex": _xy_pair(self.apex)}


@dataclass(frozen=True)
class HalfPlane(Region):
    """The side of the line x = x0 to the right (x > x0) or left (x < x0); edge as the module says."""

    side: Literal["right", "left"]
    x0: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {self.side!r}")

    @property
    def kind(self) -> str:
        return f"halfplane_{self.side}"

    def signed_distance(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        offset = xy[:, 0] - self.x0
        return -offset if self.side == "right" else offset

    def params(self) -> dict[str, Any]:
        return {"x0": float(self.x0)}


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles to [−π, π]; values already there are returned untouched so ±π/2 stays exact."""
    wrapped = np.mod(angle + np.pi, 2 * np.pi) - np.pi
    return np.where(np.abs(angle) <= np.pi, angle, wrapped)


@dataclass(frozen=True)
class PitchBeyond(Region):
    """Inside: |pitch| > limit (radians, pitch wrapped to [−π, π]); no x-y shape to draw."""

    limit: float
    KIND: ClassVar[str] = "pitch_beyond"
    uses_pitch: ClassVar[bool] = True

    def signed_distance(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        if pitch is None:
            raise ValueError("this task's rule needs the pitch angle of each state")
        # NaN pitch (undefined for the env) compares false everywhere: never inside.
        return self.limit - np.abs(wrap_angle(np.asarray(pitch, dtype=float)))

    def params(self) -> dict[str, Any]:
        return {"limit": float(self.limit)}


@dataclass(frozen=True)
class Polygon(Region):
    """Inside: the even-odd interior of the closed polygon through `vertices` (x-y, in order)."""

    vertices: tuple[tuple[float, float], ...]
    KIND: ClassVar[str] = "polygon"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "vertices", tuple((float(x), float(y)) for x, y in self.vertices))
        if len(self.vertices) < 3:
            raise ValueError(f"a polygon needs at least 3 vertices, got {len(self.vertices)}")
        if _twice_area(np.asarray(self.vertices)) == 0:
            raise ValueError("the polygon's vertices enclose no area (all on one line)")

    def signed_distance(self, xy: np.ndarray, pitch: np.ndarray | None) -> np.ndarray:
        px, py = xy[:, 0], xy[:, 1]
        nearest = np.full(len(xy), np.inf)
        inside = np.zeros(len(xy), dtype=bool)
        v = np.asarray(self.vertices)
        for (ax, ay), (bx, by) in zip(v, np.roll(v, -1, axis=0), strict=True):  # one edge at a time: O(N) memory
            ex, ey = bx - ax, by - ay
            t = np.clip(((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey or 1.0), 0.0, 1.0)
            nearest = np.minimum(nearest, np.hypot(px - (ax + t * ex), py - (ay + t * ey)))
            straddles = (ay > py) != (by > py)  # the edge crosses the horizontal ray from the point
            x_cross = ax + (py - ay) * ex / np.where(straddles, ey, 1.0)
            inside ^= straddles & (px < x_cross)
        return np.where(inside, -nearest, nearest)

    def params(self) -> dict[str, Any]:
        return {"vertices": [_xy_pair(p) for p in self.vertices]}


def _twice_area(v: np.ndarray) -> float:
    """Shoelace formula; 0 for vertices on one line."""
    return float(np.dot(v[:, 0], np.roll(v[:, 1], -1)) - np.dot(v[:, 1], np.roll(v[:, 0], -1)))
