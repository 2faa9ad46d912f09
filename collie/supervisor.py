"""The child processes of one `collie up`, supervised: a child that dies is started again after a
backoff (0.5 s, doubling to 10 s), and one that keeps dying — `max_restarts` times without staying
up `stable_s` or making progress a restart keeps (`progress`: the trainer's checkpoint) in between —
ends the stack with an error naming it and what it said. One that refuses
to run (exit 2: the trainer's, the teacher's and the labeling UI's refusals, e.g. a damaged
checkpoint, a revoked token) twice in a row ends it at once, and so does one whose `fatal` says no
restart can help (a trainer whose run failed): the same start would only end the same way. Every
start and exit is logged to OUT/logs/up.log; OUT/children.json names the live process of each part
(for tools and tests)."""

from __future__ import annotations

import contextlib
import functools
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from collie.child_log import last_error
from collie.processes import end_with_parent
from collie.startup import PART_ENV, mark
from collie.whole_files import write_whole

STOP_ORDER = ("trainer", "teacher", "labeling_ui", "service")  # producers first
BACKOFF_S, MAX_BACKOFF_S = 0.5, 10.0
AGAIN_DOUBLINGS = 2  # an early-ending part's wait grows to again_after_s × 4, no further
REFUSED = 2  # argparse's exit code, which the trainer, the teacher and the labeling UI use for their refusals too
# a part refused for memory that runs beside the stack were promised (exit EX_TEMPFAIL: the trainer's
# memory ledger) is no fault: it tries again this often until they have ended
WAIT_FOR_MEMORY_S = 15.0


class Closeable(Protocol):
    def close(self) -> None: ...


class ChildFailed(RuntimeError):
    """A supervised child died more often than the restart limit allows."""


@dataclass
class Child:
    name: str
    args: Callable[[], list[str]]  # evaluated at each start (a restarted trainer adds --resume)
    env: dict[str, str]
    # called on exit 0: is its work over (trainer, teacher: not restarted)? None: it never is (service)
    done_when_ok: Callable[[], bool] | None
    # an exit 0 before its work is over that is no failure: started again after this many seconds
    # (the teacher, when the trainer reopens a finished run); None: it counts as a death
    again_after_s: float | None = None
    # called on any other exit: why no restart can help (the trainer's run failed), else None
    fatal: Callable[[], str | None] | None = None
    pass_fds: tuple[int, ...] = ()  # inherited by each start (the service's listening socket)
    # what a restart keeps of its work (the trainer's checkpoint): a start that changed it was no
    # failure to repeat, however short; None: only staying up `stable_s` counts
    progress: Callable[[], object] | None = None
    progress_at_start: object = None
    proc: subprocess.Popen | None = None
    started_at: float = 0.0
    failures: int = 0  # deaths since it last stayed up stable_s
    restarts: int = 0
    restart_at: float | None = None
    finished: bool = False
    log_from: int = 0  # where its latest start's lines begin in its log
    early_ends: int = 0  # exits 0 in a row before its work was over, each within stable_s of its start
    exit_codes: list[int] = field(default_factory=list)


class Supervisor:
    def __init__(
        self, out: Path, max_restarts: int = 5, stable_s: float = 60.0, inherited: tuple[int, ...] = ()
    ) -> None:
        self.out, self.max_restarts, self.stable_s = out, max_restarts, stable_s
        self.inherited = inherited  # descriptors every child holds too (OUT's lock)
        self.children: dict[str, Child] = {}
        self._after_stop: list[Closeable] = []  # closed once every child is down
        (out / "logs").mkdir(parents=True, exist_ok=True)
        self._log = open(out / "logs" / "up.log", "a")  # noqa: SIM115 - lives as long as the stack

    def log(self, message: str) -> None:
        line = f"{time.strftime('%Y-%m-%d %H:%M:%S')} {message}"
        with contextlib.suppress(OSError):  # a full disk must not end the stack: up.log is its diary
            self._log.write(line + "\n")
            self._log.flush()

    def start(
        self,
        name: str,
        args: Callable[[], list[str]],
        env: dict[str, str],
        done_when_ok: Callable[[], bool] | None = None,
        pass_fds: tuple[int, ...] = (),
        again_after_s: float | None = None,
        fatal: Callable[[], str | None] | None = None,
        progress: Callable[[], object] | None = None,
    ) -> subprocess.Popen:
        child = Child(name, args, env, done_when_ok, again_after_s, fatal, pass_fds, progress)
        self.children[name] = child
        return self._spawn(child)

    def _spawn(self, child: Child) -> subprocess.Popen:
        log = open(self.out / "logs" / f"{child.name}.log", "ab")  # noqa: SIM115 - lives as long as the child
        child.log_from = log.tell()
        env = {**child.env, "PYTHONUNBUFFERED": "1", PART_ENV: child.name}  # PART_ENV: its startup marks
        child.proc = subprocess.Popen(
            [sys.executable, "-m", "collie.cli", *child.args()],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,  # our Ctrl-C is handled here, not by children
            pass_fds=child.pass_fds + self.inherited,
            # SIGTERM when `collie up` dies, even by SIGKILL (the trainer checkpoints on it); children
            # are spawned from the main thread only, whose end is what the kernel watches
            preexec_fn=functools.partial(end_with_parent, os.getpid()),
        )
        log.close()  # the child holds its own copy
        child.started_at, child.restart_at = time.monotonic(), None
        child.progress_at_start = child.progress() if child.progress is not None else None
        mark(f"spawned {child.name}")
        self.log(f"started {child.name} (pid {child.proc.pid})")
        self._write_pids()
        return child.proc

    def proc(self, name: str) -> subprocess.Popen:
        proc = self.children[name].proc
        assert proc is not None
        return proc

    def check(self) -> None:
        """Restart children that died (after their backoff); raise ChildFailed past the limit."""
        now = time.monotonic()
        for child in self.children.values():
            if child.finished or child.proc is None:
                continue
            if child.restart_at is not None:
                if child.exit_codes[-1:] == [0] and child.done_when_ok is not None and child.done_when_ok():
                    # it ended before its work was over, which is over now (the teacher of a run
                    # that finished: it sees the end before the trainer has written its last files)
                    child.finished, child.restart_at = True, None
                    self.log(f"{child.name} finished (exit 0)")
                elif now >= child.restart_at:
                    child.restarts += 1
                    self._spawn(child)
                continue
            code = child.proc.poll()
            if code is None:
                continue
            child.exit_codes.append(code)
            if code == 0 and child.done_when_ok is not None and child.done_when_ok():
                child.finished = True
                self.log(f"{child.name} finished (exit 0)")
                continue
            if code == 0 and child.again_after_s is not None:
                # doubling while it keeps ending at once (a stopped run's teacher until the trainer sees the
                # stop), to at most 4×: a resumed run's teacher waits no longer than that once it reopens
                child.early_ends = 0 if now - child.started_at >= self.stable_s else child.early_ends + 1
                delay = child.again_after_s * 2 ** min(max(child.early_ends - 1, 0), AGAIN_DOUBLINGS)
                self.log(
                    f"{child.name} ended (exit 0): its run takes no work now (finished or stopping); "
                    f"again in {delay:g} s unless the trainer is done"
                )
                child.restart_at = now + delay
                continue
            if code == os.EX_TEMPFAIL:
                said = last_error(self.out / "logs" / f"{child.name}.log", child.log_from)
                if child.exit_codes[-2:-1] != [os.EX_TEMPFAIL]:  # once per wait, not every try
                    again = f"trying again every {WAIT_FOR_MEMORY_S:g} s"
                    print(f"collie up: the {child.name} waits for memory ({said}); {again}", file=sys.stderr)
                self.log(f"{child.name} refused for memory other runs were promised; again in {WAIT_FOR_MEMORY_S:g} s")
                child.restart_at = now + WAIT_FOR_MEMORY_S
                continue
            if now - child.started_at >= self.stable_s or self._progressed(child):
                child.failures = 0
            child.failures += 1
            how = f"signal {-code}" if code < 0 else f"code {code}" + (" (interrupted)" if code == 0 else "")
            # what it said, when it ended by itself with an error (a signal's victim said nothing of it)
            said = last_error(self.out / "logs" / f"{child.name}.log", child.log_from) if code > 0 else ""
            how_said = how + (f": {said}" if said else "")
            why = child.fatal() if child.fatal is not None and code != 0 else None
            if why is not None:
                self.log(f"{child.name} exited with {how}: {why}; not restarted")
                raise ChildFailed(f"the {child.name}'s {why}")
            if child.exit_codes[-2:] == [REFUSED, REFUSED]:  # a refusal, twice: not a fault a restart mends
                self.log(f"{child.name} refused to run again ({how_said}), giving up")
                raise ChildFailed(f"the {child.name} refused to run again ({how_said})")
            if child.failures > self.max_restarts:
                self.log(f"{child.name} exited with {how_said}; {self.max_restarts} restarts did not help, giving up")
                raise ChildFailed(f"the {child.name} keeps exiting (last: {how_said})")
            delay = min(BACKOFF_S * 2 ** (child.failures - 1), MAX_BACKOFF_S)
            self.log(f"{child.name} exited with {how_said}; restarting in {delay:.1f} s")
            print(f"collie up: {child.name} exited with {how_said}; restarting in {delay:.1f} s", file=sys.stderr)
            child.restart_at = now + delay

    @staticmethod
    def _progressed(child: Child) -> bool:
        return child.progress is not None and child.progress() != child.progress_at_start

    def closing(self, thing: Closeable) -> None:
        """Close `thing` (e.g. the socket the service inherits) once the children are stopped."""
        self._after_stop.append(thing)

    def finished(self, name: str) -> bool:
        child = self.children.get(name)
        return child is not None and child.finished

    def stop(self, timeout_s: float = 15.0) -> None:
        for name in STOP_ORDER:
            child = self.children.get(name)
            if child is None or child.proc is None or child.proc.poll() is not None:
                continue
            child.proc.send_signal(signal.SIGINT if name == "trainer" else signal.SIGTERM)
            try:
                child.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                child.proc.kill()
                child.proc.wait()
        for thing in self._after_stop:
            thing.close()
        self.log("stopped")
        self._log.close()

    def _write_pids(self) -> None:
        pids = {n: c.proc.pid for n, c in self.children.items() if c.proc is not None}
        text = json.dumps({"up": os.getpid(), "children": pids}).encode()
        try:
            write_whole(self.out / "children.json", lambda f: f.write(text))
        except OSError as exc:  # a full disk: the parts still run; children.json is for tools
            print(
                f"collie up: warning: cannot write {self.out / 'children.json'}: {exc.strerror or exc}", file=sys.stderr
            )
