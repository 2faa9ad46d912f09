"""SIGTERM while `collie train` starts (its imports take seconds: torch; then envs, the epoch-0
evaluation): noted here, and the start ends as Ctrl-C does (`collie train: interrupted`, exit 130)
once it reaches `trainer.cli.run`'s check, instead of dying by the signal with no word. Light, so
`collie.cli` installs it before importing the trainer. The training loop puts its own handler over
it (a final checkpoint) and, if one came after that check (while the run resumed, rebuilt its
labels or ran its epoch-0 evaluation), stops at once, checkpointed."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

INTERRUPTED = 130  # the exit status of a command a signal ended with `collie X: interrupted` (128 + SIGINT)

# Noted, not raised: a KeyboardInterrupt raised where the signal lands may be inside a finalizer
# (GC), where Python prints it as "Exception ignored" and goes on; the start ends before training.
ASKED = threading.Event()


def _note(_signum: int, _frame: object) -> None:
    ASKED.set()


def _note_and_raise(_signum: int, _frame: object) -> None:
    ASKED.set()  # kept if the raise lands in a finalizer: the waiter's own check ends it then
    raise KeyboardInterrupt


def note_sigterm() -> None:
    signal.signal(signal.SIGTERM, _note)


@contextlib.contextmanager
def raising() -> Iterator[None]:
    """While waiting on something outside (the labeling service, up to minutes, in a connect or a
    sleep that a noted signal does not cut short): SIGTERM raises KeyboardInterrupt at once, as
    Ctrl-C does, so `docker stop` or systemd get `collie train: interrupted` before their SIGKILL.
    Main thread only (signal.signal)."""
    if ASKED.is_set():
        raise KeyboardInterrupt
    previous = signal.signal(signal.SIGTERM, _note_and_raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
