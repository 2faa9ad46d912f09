"""Signals that land at a chosen point of a child's run, however loaded the machine: the child's
startup log (COLLIE_STARTUP_LOG, collie/startup.py) is a FIFO, so each mark it writes blocks in
open() until this side reads it. The signal goes out right after the chosen mark is read and
before the next open() is answered, so the child's Python handler runs before its next mark
returns. (Reading goes on after the signal: the kernel may hand it to another of the child's
threads, and then only the main thread's return from that open() runs the handler.) A mark that
opens the FIFO in the instant between this side's end of a read and its close meets EPIPE and
opens it again (collie.startup.mark); only one that opened, wrote and closed all within that instant
would be lost, and then the signal would not go out (`sent` stays unset)."""

from __future__ import annotations

import contextlib
import os
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

from collie.schemas import StartupMark


class PacedMarks:
    def __init__(self, folder: Path) -> None:
        self.path = folder / "startup.fifo"
        os.mkfifo(self.path)
        self.env = {**os.environ, "COLLIE_STARTUP_LOG": str(self.path)}
        self.seen: list[StartupMark] = []
        self.sent = threading.Event()
        self._reader: threading.Thread | None = None

    def signal_at(self, proc: subprocess.Popen[str], at: Callable[[StartupMark], bool], sig: int) -> None:
        """Send `sig` to `proc` once a mark satisfies `at`, then read on until `proc` ends."""

        def pace() -> None:
            while proc.poll() is None:
                fd = os.open(self.path, os.O_RDONLY)  # one writer's open: one mark
                chunks = [b""]
                while chunks[-1] or len(chunks) == 1:
                    chunks.append(os.read(fd, 65536))
                os.close(fd)  # at once after the end: a mark that opens before this may meet EPIPE and open again
                marks = [StartupMark.model_validate_json(line) for line in b"".join(chunks).splitlines()]
                self.seen += marks
                if not self.sent.is_set() and any(at(m) for m in marks):
                    proc.send_signal(sig)
                    self.sent.set()

        self._reader = threading.Thread(target=pace, daemon=True)
        self._reader.start()

    def release(self) -> None:
        """Once the child is gone: answer the reading thread's open(), however late it gets there
        (a writer's open fails while no reader waits), until the thread has ended."""
        deadline = time.monotonic() + 30
        while self._reader is not None and self._reader.is_alive() and time.monotonic() < deadline:
            with contextlib.suppress(OSError):
                os.close(os.open(self.path, os.O_WRONLY | os.O_NONBLOCK))
            self._reader.join(0.1)
