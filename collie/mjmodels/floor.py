"""A floor whose colour encodes position, so an agent that sees only pixels can tell where it is
(the "coloured floor" of METRA and COLLIE's pixel experiments).

Red grows with x and green with y across the square [−L, L]² (absolute position, coarse); blue
alternates on a 1 m checkerboard (motion, fine: the red/green gradient changes only about 3 levels
per metre). The texture is written into the compiled model's `tex_data`, which is what the GL
context uploads, so the MJCF text stays self-contained and a viewer calls `paint_floor` too.
"""

from __future__ import annotations

import mujoco
import numpy as np

HALF_EXTENT = 40.0  # L, metres: far beyond what a 200-step episode reaches
TEXTURE_TEXELS = 1024  # per side: ≈ 13 texels per checker tile
TILE = 1.0  # checker tile side, metres
TEXTURE = "position_floor"  # name of the texture (and material) the floor geom uses


def floor_colour(x: np.ndarray, y: np.ndarray, half_extent: float = HALF_EXTENT) -> np.ndarray:
    """(..., 3) uint8 floor colour at world positions (x, y)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    u = np.clip((x + half_extent) / (2 * half_extent), 0.0, 1.0)
    v = np.clip((y + half_extent) / (2 * half_extent), 0.0, 1.0)
    checker = (np.floor(x / TILE) + np.floor(y / TILE)) % 2
    rgb = np.stack([30 + 195 * u, 30 + 195 * v, 70 + 80 * checker], axis=-1)
    return np.round(rgb).astype(np.uint8)


def floor_texture(texels: int = TEXTURE_TEXELS, half_extent: float = HALF_EXTENT) -> np.ndarray:
    """(texels, texels, 3) uint8 image laid over the plane [−L, L]²: column ↦ x, row ↦ y.

    MuJoCo maps a plane's texture row 0 to its +y edge (checked by tests/test_pixel_envs.py)."""
    centres = (np.arange(texels) + 0.5) / texels * 2 * half_extent - half_extent
    x, y = np.meshgrid(centres, centres[::-1])
    return floor_colour(x, y, half_extent)


def paint_floor(model: mujoco.MjModel, half_extent: float = HALF_EXTENT) -> None:
    """Fill the model's `position_floor` texture (before any renderer uploads it)."""
    tex = model.texture(TEXTURE)
    h, w = int(tex.height[0]), int(tex.width[0])
    if h != w or model.tex_nchannel[tex.id] != 3:
        raise ValueError(f"{TEXTURE} must be a square RGB texture, got {w}×{h}×{model.tex_nchannel[tex.id]}")
    start = int(tex.adr[0])
    model.tex_data[start : start + h * w * 3] = floor_texture(h, half_extent).reshape(-1)


def add_floor_material(spec: mujoco.MjSpec, floor_geom: str, half_extent: float = HALF_EXTENT) -> None:
    """Give `floor_geom` a placeholder texture spanning [−L, L]² once, to be painted after compiling."""
    spec.add_texture(
        name=TEXTURE,
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_FLAT,
        width=TEXTURE_TEXELS,
        height=TEXTURE_TEXELS,
        rgb1=[0.5, 0.5, 0.5],
    )
    material = spec.add_material(name=TEXTURE, texrepeat=[1, 1], texuniform=False)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = TEXTURE
    floor = spec.geom(floor_geom)
    # The third size is the spacing of the quads a plane is drawn with: dm_control's 0.2–0.5 m makes
    # 10⁵ quads that cost Mesa ≈ 1.5 ms a frame; 2 m renders ≈ 6× faster and looks the same.
    floor.size = [half_extent, half_extent, 2.0]
    floor.material = TEXTURE
