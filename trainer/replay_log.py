"""The replay buffer on disk as append-only chunk files, so a checkpoint costs what changed.

Every checkpoint writes the trajectories stored since the previous one as one chunk,
OUT/replay/NNNNNN.npz (uncompressed: those trajectories' arrays and slot numbers), then the
checkpoint itself names the chunks that still hold a live trajectory, with the ring's `next` and `count`. Restoring
applies those chunks in order (a later chunk overwrites a reused slot). A chunk whose slots have
all been overwritten since is deleted only after the checkpoint that no longer names it is on
disk, and a chunk written after the last checkpoint (a crash in between) is ignored, so
`--resume` sees exactly the replay of the checkpoint it loads.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from trainer.replay import FIELDS, TrajectoryReplay
from trainer.run_files import ResumeError


class ReplayLog:
    def __init__(self, folder: Path, replay: TrajectoryReplay) -> None:
        self.folder, self.replay = folder, replay
        self.owner = np.full(replay.size, -1, np.int64)  # slot → the chunk holding its latest write
        self.next_chunk = 0

    def path(self, chunk: int) -> Path:
        return self.folder / f"{chunk:06d}.npz"

    def live_chunks(self) -> list[int]:
        return sorted(int(c) for c in np.unique(self.owner[self.owner >= 0]))

    def flush(self) -> dict[str, Any]:
        """Write the dirty slots as a new chunk; returns the checkpoint's record of the replay."""
        r = self.replay
        slots = np.flatnonzero(r.dirty)
        if len(slots):
            self.folder.mkdir(parents=True, exist_ok=True)
            chunk = {key: getattr(r, key)[slots] for key in FIELDS} | {"slots": slots}
            final = self.path(self.next_chunk)
            tmp = final.with_suffix(".tmp")
            with open(tmp, "wb") as f:
                np.savez(f, **chunk)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, final)
            self.owner[slots] = self.next_chunk
            self.next_chunk += 1
            r.dirty[:] = False
        return {"chunks": self.live_chunks(), "next": r.next, "count": r.count, "next_chunk": self.next_chunk}

    def prune(self) -> None:
        """Delete chunk files no live slot refers to (call after the checkpoint is on disk)."""
        live = set(self.live_chunks())
        for f in self.folder.glob("*.npz") if self.folder.exists() else ():
            if f.stem.isdigit() and int(f.stem) not in live:
                f.unlink()

    def restore(self, record: dict[str, Any]) -> None:
        """Rebuild the replay of a checkpoint from its chunks."""
        r = self.replay
        self.owner[:] = -1
        for chunk in record["chunks"]:
            path = self.path(chunk)
            if not path.exists():
                raise ResumeError(f"replay chunk {path} named by the checkpoint is missing")
            try:
                with np.load(path) as data:
                    slots = data["slots"]
                    if slots.dtype.kind not in "iu" or (len(slots) and not 0 <= slots.min() <= slots.max() < r.size):
                        raise IndexError(f"its slots are not within this run's replay of {r.size} trajectories")
                    for key in FIELDS:
                        getattr(r, key)[slots] = data[key]
            except (OSError, ValueError, KeyError, EOFError, IndexError, zipfile.BadZipFile, zlib.error) as exc:
                # truncated, overwritten, or another run's (slots beyond this replay's, arrays of other shapes)
                raise ResumeError(f"replay chunk {path} is damaged ({type(exc).__name__}: {exc})") from None
            self.owner[slots] = chunk
        r.next, r.count = int(record["next"]), int(record["count"])
        r.dirty[:] = False
        self.next_chunk = int(record["next_chunk"])
