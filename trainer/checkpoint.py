"""Checkpoints that a crash cannot corrupt: written to a temporary file, then atomically renamed."""

from __future__ import annotations

import os
import pickle
import zipfile
from pathlib import Path
from typing import Any

import torch


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(state, tmp)
    with open(tmp, "rb") as f:
        os.fsync(f.fileno())
    os.replace(tmp, path)


class ResumeError(ValueError):
    """A run folder that `--resume` cannot continue: a file missing or damaged, named in the message."""


def load_checkpoint(path: Path) -> dict[str, Any]:
    if not path.exists():
        raise ResumeError(f"no checkpoint at {path}: nothing to resume")
    try:
        return torch.load(path, map_location="cpu", weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError, pickle.UnpicklingError, zipfile.BadZipFile) as exc:
        # torch.load's errors on a truncated or overwritten file are long and name no file
        raise ResumeError(f"{path} is damaged or truncated and cannot be resumed ({type(exc).__name__})") from None
