"""Replay pacing: a playhead over a segment's frames, advanced by a thread at ≤ 30 Hz.

viser coalesces updates faster than about 30 Hz, so the display rate is capped there; the segment's
own rate (env steps per second) times the speed decides how far the playhead moves per tick, and
the pose between two frames is interpolated, so 0.25× is smooth and 4× skips frames.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

MAX_HZ = 30.0
SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0)


class Player:
    """Play / pause, loop, speed, frame step and scrub over `n_frames` frames. `render(position)`
    is called from the player's thread with a fractional frame index whenever it changes;
    `on_frame(frame, playing)` when the whole frame number or the play state changes."""

    def __init__(
        self,
        render: Callable[[float], None],
        on_frame: Callable[[int, bool], None] | None = None,
        fps: float = 20.0,
        max_hz: float = MAX_HZ,
    ) -> None:
        self.render = render
        self.on_frame = on_frame or (lambda frame, playing: None)
        self.fps = fps
        self.tick_s = 1.0 / min(max_hz, MAX_HZ)
        self.speed = 1.0
        self.loop = True
        self.autoplay = True  # a new segment starts playing (bench_labeling's diagnostic turns it off)
        self.n_frames = 0
        self.position = 0.0
        self.playing = False
        self.ticks = 0  # renders done while playing (benchmarks read the achieved rate)
        self.tick_work_s = 0.0  # time those renders took, summed
        self._shown = -1.0
        self._reported = (-1, False)
        self._wake = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="collie-player", daemon=True)
        self._thread.start()

    # ---------------------------------------------------------------- commands

    def load(self, n_frames: int, play: bool = True) -> None:
        """A new segment: show its first frame now (from the caller's thread) and start playing."""
        with self._wake:
            self.n_frames = n_frames
            self.position = 0.0
            self.playing = play and self.autoplay and n_frames > 1
            self._shown = -1.0
            self._draw()
            self._wake.notify()

    def unload(self) -> None:
        with self._wake:
            self.n_frames = 0
            self.playing = False

    def replay(self) -> None:
        self.seek(0.0, play=True)

    def toggle(self) -> None:
        with self._wake:
            if not self.playing and self.position >= self.n_frames - 1:
                self.position = 0.0  # play again from the start once the end was reached
            self.playing = not self.playing and self.n_frames > 1
            self._draw()
            self._wake.notify()

    def pause(self) -> None:
        with self._wake:
            self.playing = False
            self._draw()

    def step(self, frames: int) -> None:
        """Pause and move by whole frames."""
        with self._wake:
            self.playing = False
            self.position = float(min(max(round(self.position) + frames, 0), max(self.n_frames - 1, 0)))
            self._draw()

    def seek(self, frame: float, play: bool | None = None) -> None:
        with self._wake:
            self.position = float(min(max(frame, 0.0), max(self.n_frames - 1, 0)))
            if play is not None:
                self.playing = play and self.n_frames > 1
            self._draw()
            self._wake.notify()

    def set_speed(self, speed: float) -> None:
        self.speed = min(max(speed, SPEEDS[0]), SPEEDS[-1])

    def close(self) -> None:
        with self._wake:
            self._closed = True
            self._wake.notify()

    # ---------------------------------------------------------------- the thread

    def _draw(self) -> None:
        """Render if the playhead moved, and report frame/state changes (lock held)."""
        if self.n_frames == 0:
            return
        if self.position != self._shown:
            self._shown = self.position
            self.render(self.position)
        report = (int(self.position), self.playing)
        if report != self._reported:
            self._reported = report
            self.on_frame(*report)

    def _advance(self, elapsed: float) -> None:
        self.position += elapsed * self.fps * self.speed
        if self.loop:
            # a loop lasts n frame times: the last frame holds for one before the wrap to 0
            self.position %= self.n_frames
        elif self.position >= self.n_frames - 1:
            self.position = self.n_frames - 1.0
            self.playing = False

    def _run(self) -> None:
        last = time.perf_counter()
        due = last
        while True:
            with self._wake:
                while not self._closed and not self.playing:
                    self._wake.wait()
                    last = due = time.perf_counter()
                if self._closed:
                    return
                now = time.perf_counter()
                self._advance(now - last)
                last = now
                try:
                    self._draw()
                    self.ticks += 1
                    self.tick_work_s += time.perf_counter() - now
                except Exception:  # a vanished client: stop quietly, the session closes us
                    self.playing = False
            # a fixed schedule (not "sleep what is left of this tick") keeps the average at max_hz;
            # after a stall it restarts from now instead of bursting to catch up
            due = max(due + self.tick_s, time.perf_counter())
            time.sleep(max(0.0, due - time.perf_counter()))
