"""Image observations on the wire: H uint8 frames as one zlib-compressed, base64 string
(`PackedFrames`). As JSON numbers a 20-frame 64×64×9 pixel segment is ~3 MB; packed it is a few
hundred KB and is never parsed by the service or the labeling UI, which replay from qpos."""

from __future__ import annotations

import base64
import zlib

import numpy as np

from collie.schemas import PackedFrames


def pack_frames(frames: np.ndarray) -> PackedFrames:
    """(H, *frame_shape) uint8 → PackedFrames."""
    frames = np.ascontiguousarray(frames)
    if frames.dtype != np.uint8 or frames.ndim < 2:
        raise ValueError(f"pack_frames takes (H, ...) uint8 frames, got {frames.dtype} {frames.shape}")
    data = base64.b64encode(zlib.compress(frames.tobytes(), level=1)).decode("ascii")
    return PackedFrames(dtype="uint8", n=len(frames), shape=list(frames.shape[1:]), zlib_b64=data)


def unpack_frames(packed: PackedFrames) -> np.ndarray:
    """PackedFrames → (H, *frame_shape) uint8 (the schema checked the size when it was built)."""
    raw = zlib.decompress(base64.b64decode(packed.zlib_b64))
    return np.frombuffer(raw, dtype=np.uint8).reshape(packed.n, *packed.shape).copy()
