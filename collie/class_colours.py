"""One colour per label class wherever a person sees the classes, as in the paper's figures:
undesirable (bad) red, neutral green, desirable (good) yellow. The plots, the labeling UI and the
dashboard (web/js/regions.js, which a test holds equal to these) all draw with them, so a colour
means the same class on every screen."""

from __future__ import annotations

from collie.tasks import BAD, GOOD, NEUTRAL

RGB = tuple[int, int, int]

STRONG: dict[int, str] = {BAD: "#d62728", NEUTRAL: "#2ca02c", GOOD: "#e6b800"}  # marks, lines, edges
PALE: dict[int, str] = {BAD: "#f9d9d9", NEUTRAL: "#d9efd9", GOOD: "#fbefb8"}  # areas


def to_rgb(hex_colour: str) -> RGB:
    value = int(hex_colour.lstrip("#"), 16)
    return (value >> 16, (value >> 8) & 0xFF, value & 0xFF)
