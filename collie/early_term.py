"""SIGTERM while `collie train` starts (its imports take seconds: torch; then envs, the epoch-0
evaluation): noted here, and the start ends as Ctrl-C does (`collie train: interrupted`, exit 130)
once it reaches `trainer.cli.run`'s check, instead of dying by the signal with no word. Light, so
`collie.cli` installs it before importing the trainer. The training loop puts its own handler over
it (a final checkpoint) and, if one came after that check (while the run resumed, rebuilt its
labels or ran its epoch-0 evaluation), stops at once, checkpointed."""

from __future__ import annotations

import signal
import threading

# Noted, not raised: a KeyboardInterrupt raised where the signal lands may be inside a finalizer
# (GC), where Python prints it as "Exception ignored" and goes on; the start ends before training.
ASKED = threading.Event()


def _note(_signum: int, _frame: object) -> None:
    ASKED.set()


def note_sigterm() -> None:
    signal.signal(signal.SIGTERM, _note)
