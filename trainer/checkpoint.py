"""Checkpoints that a crash cannot corrupt: written to a temporary file, then atomically renamed."""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path
from typing import Any, BinaryIO

import torch

from collie.whole_files import write_whole
from trainer.run_files import ResumeError


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    """A failed save (a full disk) leaves the last checkpoint as it was, and no partial file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_whole(path, lambda f: torch_save(state, f), sync=True)


def torch_save(state: dict[str, Any], f: BinaryIO) -> None:
    """torch.save, raising the file system's refusal itself: torch's zip writer, closing the file
    after a write failed (a full disk), raises its own RuntimeError over it ("unexpected pos …")."""
    try:
        torch.save(state, f)
    except RuntimeError as exc:
        if isinstance(exc.__context__, OSError):
            raise exc.__context__ from None
        raise


def load_checkpoint(path: Path) -> dict[str, Any]:
    if not path.exists():
        raise ResumeError(f"no checkpoint at {path}: nothing to resume")
    try:
        return torch.load(path, map_location="cpu", weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError, pickle.UnpicklingError, zipfile.BadZipFile) as exc:
        # torch.load's errors on a truncated or overwritten file are long and name no file
        raise ResumeError(f"{path} is damaged or truncated and cannot be resumed ({type(exc).__name__})") from None
