"""Signals that land at a chosen point of a child's run, however loaded the machine: the child's
startup log (COLLIE_STARTUP_LOG, collie/startup.py) is a FIFO, and each mark it writes opens it,
which blocks while no reader has it open. This side keeps it open for reading only while it reads,
closes it after each read, sends the signal if the chosen mark came, and opens it again: the next
mark's open() waits in between, so the child's Python handler runs before its next mark returns.
(Reading goes on after the signal: the kernel may hand it to another of the child's threads, and
then only the main thread's return from that open() runs the handler.)

This side also holds the FIFO open for writing, so a mark written in the instant between a read
and the close stays in the pipe for the next read instead of being dropped with it; a mark that
opened then and writes after the close meets EPIPE and opens again (collie.startup.mark). No mark
is lost; one that opened in that instant is not held back, so the signal may land a mark later."""

from __future__ import annotations

import os
import select
import subprocess
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from collie.schemas import StartupMark


class PacedMarks:
    def __init__(self, folder: Path) -> None:
        self.path = folder / "startup.fifo"
        os.mkfifo(self.path)
        self.env = {**os.environ, "COLLIE_STARTUP_LOG": str(self.path)}
        self.seen: list[StartupMark] = []
        self.sent = threading.Event()
        self._stop = threading.Event()
        self._reader: threading.Thread | None = None

    def signal_at(self, proc: subprocess.Popen[str], at: Callable[[StartupMark], bool], sig: int) -> None:
        """Send `sig` to `proc` once a mark satisfies `at`, then read on until `proc` ends."""
        # Opened here, before the child can mark: neither open waits (the read end is non-blocking,
        # and the write end has that reader).
        reading = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
        keeping = os.open(self.path, os.O_WRONLY | os.O_NONBLOCK)

        def pace() -> None:
            nonlocal reading
            rest = b""
            try:
                while not self._stop.is_set():
                    if not select.select([reading], [], [], 0.1)[0]:
                        if proc.poll() is not None:
                            return  # gone, and nothing left unread
                        continue
                    data = os.read(reading, 65536)
                    os.close(reading)  # the next mark's open() waits from here
                    *lines, rest = (rest + data).split(b"\n")
                    marks = [StartupMark.model_validate_json(line) for line in lines if line]
                    self.seen += marks
                    if not self.sent.is_set() and any(at(m) for m in marks):
                        proc.send_signal(sig)
                        self.sent.set()
                    reading = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)  # and goes on from here
            finally:
                os.close(reading)
                os.close(keeping)

        self._reader = threading.Thread(target=pace, daemon=True)
        self._reader.start()

    def release(self) -> None:
        """Once the child is gone: end the reading thread."""
        self._stop.set()
        if self._reader is not None:
            self._reader.join(30)

    def run(
        self, cmd: list[str], at: Callable[[StartupMark], bool], sig: int, timeout_s: float = 180, **popen: Any
    ) -> tuple[int, str]:
        """`cmd` (its startup log this FIFO), sent `sig` once a mark satisfies `at`, run to its end:
        its exit status and stderr, the signal checked as sent."""
        proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, **{"env": self.env, **popen})
        self.signal_at(proc, at, sig)
        try:
            _, err = proc.communicate(timeout=timeout_s)
        finally:
            proc.kill()
            self.release()
        assert self.sent.is_set(), err[-3000:]
        return proc.returncode, err
