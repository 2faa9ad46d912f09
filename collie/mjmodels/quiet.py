"""Compile Gymnasium's MJCF files without MuJoCo 3.17's deprecation noise.

half_cheetah.xml uses `settotalmass`, which MuJoCo 3.17 still honours but reports as deprecated
on every compile: on stderr and, worse, appended to a MUJOCO_LOG.TXT in the working directory.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager

import mujoco

_HARMLESS = ("compiler attribute 'settotalmass' is deprecated",)


def _forward(message: str) -> None:
    if not message.startswith(_HARMLESS):
        warnings.warn(f"MuJoCo: {message}", RuntimeWarning, stacklevel=2)


@contextmanager
def quiet_compile() -> Iterator[None]:
    """Drop the known-harmless compiler warnings; any other MuJoCo warning becomes a Python warning."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(_forward)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)
