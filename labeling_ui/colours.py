"""The path colours, one set for the 3D view (scene.py), the inset (inset.py) and the legend
(panels.py), so what a colour means is the same everywhere."""

from __future__ import annotations

RGB = tuple[int, int, int]

TO_COME_RGB: RGB = (255, 150, 30)  # the segment (in 3D: the part still to play)
PLAYED_RGB: RGB = (230, 40, 120)  # the part already played (3D only: the inset has no playhead)
EARLIER_RGB: RGB = (90, 90, 90)  # the trajectory before the segment
NORTH_RGB: RGB = (40, 90, 220)


def css(rgb: RGB) -> str:
    return "#" + "".join(f"{c:02x}" for c in rgb)
