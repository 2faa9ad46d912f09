"""`collie sweep`: methods × tasks × seeds of `collie train`, each run its own process (one torch
thread), `--jobs` at a time on this machine, or on a Ray cluster when `--ray ADDRESS` is given.

Resumable: a run folder whose summary.json says "finished" is not rerun unless the command asks
only for more --epochs: then it is extended from its checkpoint as `collie train --resume --epochs N`
would (one of another configuration is named in a warning with the keys that differ, of those that
matter to its method); a run with a checkpoint continues from it (`collie train --resume`); a run
stopped before its last epoch (SIGINT, SIGTERM) is reported as failed and never evaluated; with
`--downstream`, a run whose downstream.json already holds its task from its final policy is not
re-evaluated. Ctrl-C, SIGTERM or SIGHUP of a sweep starts no further run and hands each running
`collie train` one SIGTERM (it writes a final checkpoint; rerunning the sweep resumes it), on Ray
through `ray.cancel` of each run's task. Folders:
OUT/<env>-<task>-<method>[+<variant>]-s<seed>, each with sweep_run.json naming its method and variant
for `collie report`, and the preset and train flags it runs with (a run resumed with its own keeps
the one it began with). After the runs, the report of OUT is written to OUT/report/.

    collie sweep --env point --tasks north,range --methods metra,collie --seeds 3 --out runs/sweep
    collie sweep --methods collie --variant additive --out runs/ablations -- --reward-form additive
    collie sweep --task-file charger.toml --methods metra,collie --out runs/charger   # a task from a file
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import json
import os
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, NoReturn

from collie.early_term import INTERRUPTED
from collie.pass_through import owned_flags
from collie.processes import end_with_parent
from collie.whole_files import make_folder
from trainer.config import PRESETS, flag
from trainer.methods import METHODS, matters
from trainer.metrics import BIN_RULES
from trainer.run_files import RunFolderError, has_checkpoint, read_json_object, write_json, writing_into
from trainer.same_run import RULE, comparable, differing_keys, only_more_epochs, rule_digest, run_config

HEAD_TIMEOUT_S = 10.0  # how long `--ray ADDRESS`'s port may take to accept a connection
SHOWN_KEYS = 4  # a warning names at most this many differing config keys with their values
POLL_S = 0.5  # how often a wait looks up from a child process or the cluster (a stop asked, a Ray cancel)
# how long a stopped run may take to write its final checkpoint (the rest of its epoch) and end
STOP_WAIT_S = 300.0


class Interrupted(RuntimeError):
    """A run the sweep did not start because it was told to stop."""


class StoppedEarly(RuntimeError):
    """A run whose training ended before its last epoch (a signal: it wrote a final checkpoint)."""


class Stop:
    """A sweep (or a Ray task's run) told to end: no run starts after it, and each running child
    process gets one SIGTERM, however many signals the sweep gets (children run in their own
    session, so a terminal's Ctrl-C reaches only the sweep; a trainer's second signal would skip its
    final checkpoint). Children also get SIGTERM if the sweep itself is killed. In a Ray worker the
    stop is the sweep's `ray.cancel`, which raises KeyboardInterrupt in the task (`_wait`)."""

    def __init__(self) -> None:
        self.asked = threading.Event()
        self._running: set[subprocess.Popen] = set()
        self._lock = threading.Lock()  # taken by the workers and the handler, never held by the main thread
        self._ended = threading.Condition(self._lock)  # told as each child ends
        self._freeing_ends = 0  # children that ended other than refused for memory: each may have freed some

    def handle(self, _signum: int, _frame: object) -> None:
        if self.asked.is_set():
            return
        self.asked.set()
        with self._lock:
            for proc in self._running:
                proc.send_signal(signal.SIGTERM)

    def run(self, cmd: list[str], **popen: Any) -> int:
        """`cmd`'s exit code; Interrupted without starting it once the sweep was told to stop. A
        Ray cancel (KeyboardInterrupt) landing anywhere in here stops the child as a signal would."""
        proc: subprocess.Popen | None = None
        try:
            with self._lock:  # the handler signals every child registered before it, none twice
                if self.asked.is_set():
                    raise Interrupted("not started: the sweep was interrupted")
                # spawned by the pool's threads, which live until every run is over (what PDEATHSIG watches)
                parent_death = functools.partial(end_with_parent, os.getpid())
                proc = subprocess.Popen(cmd, start_new_session=True, preexec_fn=parent_death, **popen)
                self._running.add(proc)
            return self._wait(proc)
        except KeyboardInterrupt:
            if proc is None:
                raise Interrupted("not started: the sweep was interrupted") from None
            return self._stop_and_wait(proc)
        finally:
            if proc is not None:
                with self._ended:
                    self._running.discard(proc)
                    self._freeing_ends += proc.returncode != os.EX_TEMPFAIL
                    self._ended.notify_all()

    def freeing_ends(self) -> int:
        with self._lock:
            return self._freeing_ends

    def must_wait(self, seen: int) -> bool:
        """Whether `wait_for_memory(seen)` would wait now."""
        with self._lock:
            return self._freeing_ends == seen and bool(self._running)

    def wait_for_memory(self, seen: int) -> bool:
        """Wait until more children than `seen` have ended other than refused for memory (at once
        if they have): True then; False once none runs (the memory is held by no run of this
        sweep), or once the sweep is told to stop. Polled, as `_wait`, for a Ray cancel."""
        with self._ended:
            while self._freeing_ends == seen and self._running and not self.asked.is_set():
                self._ended.wait(POLL_S)
            return self._freeing_ends != seen and not self.asked.is_set()

    def _wait(self, proc: subprocess.Popen) -> int:
        """`proc`'s exit code, polled: Ray's cancellation of a task is a KeyboardInterrupt raised
        between bytecodes, never inside a blocking wait."""
        while True:
            try:
                return proc.wait(timeout=POLL_S)
            except subprocess.TimeoutExpired:
                continue

    def _stop_and_wait(self, proc: subprocess.Popen) -> int:
        """`proc` stopped as a signal to the sweep would stop it (one SIGTERM), and waited for
        (StoppedEarly if it outlasts STOP_WAIT_S)."""
        with self._lock:
            registered = proc in self._running  # not when the cancel landed between Popen and add
        self.handle(signal.SIGINT, None)  # signals the registered children, once
        if not registered:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGTERM)
        try:
            return proc.wait(timeout=STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            raise StoppedEarly(f"pid {proc.pid} did not end {STOP_WAIT_S:.0f} s after its SIGTERM") from None


@dataclass(frozen=True)
class RunSpec:
    env: str
    task: str
    method: str
    seed: int
    out: str  # the run folder
    preset: str = "cpu"
    variant: str = ""  # a name for extra flags (an ablation), part of the folder name and report label
    flags: tuple[str, ...] = ()  # extra `collie train` flags
    downstream: bool = False
    downstream_flags: tuple[str, ...] = field(default=())
    task_file: str = ""  # the file that defines `task` (`collie sweep --task-file`), absolute


def run_folder(root: str | Path, env: str, task: str, method: str, seed: int, variant: str = "") -> Path:
    label = f"{method}+{variant}" if variant else method
    return Path(root) / f"{env}-{task}-{label}-s{seed}"


def grid(
    root: str | Path,
    env: str,
    tasks: list[str],
    methods: list[str],
    seeds: list[int],
    task_files: dict[str, str] | None = None,
    **kw: Any,
) -> list[RunSpec]:
    """Every (task, method, seed) as a RunSpec under `root`, seed by seed (a sweep cut short still
    holds whole comparisons); `task_files`: the file of each task that comes from one."""
    variant, files = kw.get("variant", ""), task_files or {}
    return [
        RunSpec(env, t, m, s, str(run_folder(root, env, t, m, s, variant)), task_file=files.get(t, ""), **kw)
        for s in seeds
        for t in tasks
        for m in methods
    ]


def is_finished(out: str | Path) -> bool:
    """summary.json says "finished". An unreadable one is not: the sweep trains (resumes) that run
    again, which rewrites it; `collie report` and `collie archive` name it and leave it out."""
    summary = Path(out) / "summary.json"
    if not summary.exists():
        return False
    try:
        return read_json_object(summary).get("status") == "finished"
    except RunFolderError:
        return False


def intended_config(spec: RunSpec) -> dict[str, Any] | None:
    """The config `collie train` makes of `spec`'s command, with its task file's RULE (None if it
    would refuse it)."""
    from trainer import cli as train_cli
    from trainer.task_choice import choose_rule

    parser = _TrainParser(prog="collie train")
    train_cli.add_arguments(parser)
    try:
        cfg = train_cli.config_from_args(parser.parse_args(train_argv(spec)))
        rule = choose_rule(cfg).definition if cfg.task_file else None
    except (_Refusal, ValueError):
        return None
    return cfg.to_dict() | ({RULE: rule_digest(rule.to_json())} if rule is not None else {})


def config_change(
    spec: RunSpec, besides: tuple[str, ...] = (), every_key: bool = False
) -> tuple[list[str], dict[str, Any], dict[str, Any]]:
    """The keys in which the run in `spec.out` differs from what `spec`'s command would make (where
    and how it ran aside: trainer.same_run.NOT_THE_RUN, and `besides`; and, unless `every_key`, keys
    that do not matter to its method, trainer.methods.matters: `--diayn` to METRA), and both configs, comparable; no
    keys if either config is unknown."""
    folder = Path(spec.out)
    try:  # a run killed before its first summary.json has its config.json alone
        made = run_config(folder)
    except RunFolderError:
        return [], {}, {}
    asked = intended_config(spec)
    if not made or asked is None:
        return [], {}, {}
    keys = [k for k in differing_keys(made, asked, besides) if every_key or matters(k, spec.method)]
    return keys, comparable(made), comparable(asked)


def shown_values(keys: list[str], made: dict[str, Any], asked: dict[str, Any]) -> str:
    """ "--hidden 32, not 48; …": each differing key's value in the run, then in the command."""
    said = lambda k: "the task file's rule" if k == RULE else flag(k)  # noqa: E731
    values = "; ".join(f"{said(k)} {made.get(k)}, not {asked.get(k)}" for k in keys[:SHOWN_KEYS])
    return values + (f" and {len(keys) - SHOWN_KEYS} more" if len(keys) > SHOWN_KEYS else "")


def extension(spec: RunSpec) -> tuple[int, int] | None:
    """(its epochs, the new ones) for a finished run that only more --epochs would change and that
    has the checkpoint to resume from: the sweep extends it, as `collie train --resume --epochs N`
    does exactly; None otherwise."""
    keys, made, asked = config_change(spec)
    if not only_more_epochs(keys, made, asked) or not has_checkpoint(spec.out):
        return None
    return made["epochs"], asked["epochs"]


def keeps_its_record(spec: RunSpec) -> bool:
    """A run resumed from its checkpoint that `spec`'s command would make otherwise keeps its
    sweep_run.json: `collie train --resume` keeps the run's config (more epochs aside), and the
    command's flags written there would name flags it does not run with (the warnings' `recorded`)."""
    folder = Path(spec.out)
    if not (has_checkpoint(folder) and (folder / "sweep_run.json").exists()):
        return False
    keys, made, asked = config_change(spec, every_key=True)  # a flag it does not read is one it does not run with
    return bool(keys) and not only_more_epochs(keys, made, asked)


def to_train(spec: RunSpec) -> bool:
    """Not finished (or never begun), or finished and to be extended to more epochs."""
    return not is_finished(spec.out) or extension(spec) is not None


def made_otherwise(spec: RunSpec) -> str | None:
    """How a finished run that is not rerun differs from what `spec`'s command would make: its
    recorded preset and train flags (sweep_run.json) against `spec`'s, then each differing key's
    values; None if it is the same run or is extended. New flags would silently not apply to it."""
    keys, made, asked = config_change(spec)
    if not keys or extension(spec) is not None:
        return None
    values = shown_values(keys, made, asked)
    grew = only_more_epochs(keys, made, asked)
    return f"{recorded(spec)} ({values}{'; no checkpoint.pt to extend it from' if grew else ''})"


def recorded(spec: RunSpec) -> str:
    """ "--preset P -- FLAGS, not …": the run's recorded command (sweep_run.json) against `spec`'s,
    or "another configuration" where there is no record or it reads the same."""
    try:
        made = read_json_object(Path(spec.out) / "sweep_run.json")
    except RunFolderError:
        return "another configuration"
    old_preset, old_flags = made.get("preset"), tuple(made.get("flags") or ())
    if (old_preset, old_flags) == (spec.preset, spec.flags):
        return "another configuration"

    def shown(preset: Any, flags: tuple[Any, ...]) -> str:
        return f"--preset {preset} -- {shlex.join(map(str, flags))}" if flags else f"--preset {preset}, no train flags"

    return f"{shown(old_preset, old_flags)}, not {shown(spec.preset, spec.flags)}"


def train_command(spec: RunSpec) -> list[str]:
    resume = ["--resume"] if has_checkpoint(spec.out) else []
    return [sys.executable, "-m", "collie.cli", "train", *train_argv(spec), *resume]


def train_argv(spec: RunSpec) -> list[str]:
    """`collie train`'s arguments for `spec` (a resume aside)."""
    return [
        "--env",
        spec.env,
        "--task",
        spec.task,
        *(("--task-file", spec.task_file) if spec.task_file else ()),
        "--method",
        spec.method,
        "--preset",
        spec.preset,
        "--seed",
        str(spec.seed),
        "--out",
        spec.out,
        "--threads",
        "1",
        "--no-progress",
        *spec.flags,
    ]


def downstream_done(out: str | Path) -> bool:
    """downstream.json holds results, each from the run's final policy (its `epoch` is the run's
    `epochs_done`): a result from an earlier policy is stale and is computed again."""
    path, summary = Path(out) / "downstream.json", Path(out) / "summary.json"
    if not (path.exists() and summary.exists()):
        return False
    results, done = json.loads(path.read_text()), json.loads(summary.read_text()).get("epochs_done")
    return bool(results) and all(r.get("epoch", done) == done for r in results.values() if isinstance(r, dict))


def _call(cmd: list[str], log: Path, stop: Stop) -> None:
    """`cmd`, logged to `log`; RuntimeError naming the log if it fails. One refused only for the
    memory running runs were promised (exit EX_TEMPFAIL: trainer/memory_ledger.py) starts again
    once a run of this sweep has ended since it started (one not refused so itself); where none
    runs, the memory is held elsewhere, and it fails. (Under Ray a task sees no other run: it fails.)"""
    from tqdm import tqdm

    log.parent.mkdir(parents=True, exist_ok=True)
    while True:
        seen = stop.freeing_ends()  # an end from now on may free what this one is refused for
        with open(log, "a") as f:
            code = stop.run(cmd, stdout=f, stderr=subprocess.STDOUT, env={**os.environ, "OMP_NUM_THREADS": "1"})
        if code != os.EX_TEMPFAIL:
            break
        if stop.must_wait(seen):
            said = f"collie sweep: {log.with_suffix('')} waits for a run to end: it needs memory promised to them"
            tqdm.write(said, file=sys.stderr)
        if not stop.wait_for_memory(seen):
            if stop.asked.is_set():
                raise Interrupted("not started: the sweep was interrupted")
            break
    if code == INTERRUPTED and stop.asked.is_set():  # the sweep's SIGTERM came before its loop: not a failure
        raise StoppedEarly(f"stopped while it started, before its first epoch: {shlex.join(cmd)}")
    if code != 0:
        raise RuntimeError(f"failed ({code}): {shlex.join(cmd)} — see {log}")


def run_downstream_task(out: Path, flags: tuple[str, ...] = (), stop: Stop | None = None) -> None:
    """`python -m trainer.downstream OUT` in its own one-thread process, logged beside the run folder
    (OUT.downstream.log); raises RuntimeError naming the log if it fails."""
    cmd = [sys.executable, "-m", "trainer.downstream", str(out), *flags]
    _call(cmd, out.with_suffix(".downstream.log"), stop or Stop())


def run_one(spec: RunSpec, stop: Stop | None = None) -> dict[str, Any]:
    """Train (or resume, or skip) one run, then its downstream task if asked; returns summary.json.
    `stop`: the local sweep's (a Ray task runs without one)."""
    out, stop = Path(spec.out), stop or Stop()
    if stop.asked.is_set():
        raise Interrupted("not started: the sweep was interrupted")
    if to_train(spec):
        out.mkdir(parents=True, exist_ok=True)
        if not keeps_its_record(spec):
            write_json(out / "sweep_run.json", asdict(spec))
        _call(train_command(spec), out.with_suffix(".log"), stop)
        if not is_finished(out):  # stopped by SIGINT / SIGTERM: a final checkpoint, not a final policy
            summary = out / "summary.json"
            status = json.loads(summary.read_text()).get("status") if summary.exists() else None
            raise StoppedEarly(f"{out} stopped before its last epoch (status {status!r}); rerun the sweep to resume it")
    if spec.downstream and not downstream_done(out):
        run_downstream_task(out, spec.downstream_flags, stop)
    return json.loads((out / "summary.json").read_text())


def run_all(
    specs: list[RunSpec], jobs: int = 1, ray_address: str | None = None, stop: Stop | None = None
) -> Iterator[tuple[RunSpec, dict[str, Any] | Exception]]:
    """Yield (spec, summary or the exception it raised) as runs end; `stop` ends them early. Local:
    `jobs` runs at a time, each a child process. Ray: one task per run (1 CPU each) on the cluster
    at `ray_address`; the run folders must be on a file system the cluster's nodes share."""
    stop = stop or Stop()
    if ray_address:
        yield from _run_on_ray(specs, connect_ray(ray_address), stop)
        return
    with ThreadPoolExecutor(max(1, jobs)) as pool:
        futures = {pool.submit(run_one, s, stop): s for s in specs}
        for fut in as_completed(futures):
            exc = fut.exception()
            yield futures[fut], (exc if isinstance(exc, Exception) else fut.result())


def connect_ray(address: str) -> Any:
    """The `ray` module, connected to the cluster at `address` (once per process); RuntimeError
    saying why not."""
    try:
        ray = importlib.import_module("ray")
    except ModuleNotFoundError as exc:
        raise RuntimeError("--ray needs the `ray` package on this machine and the cluster (pip install ray)") from exc
    if ray.is_initialized():
        return ray
    head = address.removeprefix("ray://")  # a Ray client address names the head's host and port too
    host, _, port = head.rpartition(":")
    if host:  # not "auto" (ray_address_problem passed it): ray.init retries a silent address forever, deaf to Ctrl-C
        try:
            socket.create_connection((host.strip("[]"), int(port)), timeout=HEAD_TIMEOUT_S).close()
        except OSError as exc:
            raise RuntimeError(f"--ray {address}: no Ray head answers at that address ({exc})") from None
    try:
        ray.init(address=address)
    except ValueError as exc:  # an address Ray cannot parse, should one pass ray_address_problem
        raise RuntimeError(f"--ray {address}: {exc}") from None
    return ray


def ray_address_problem(address: str) -> str | None:
    """Why `address` is no Ray address (`ray.init` raises a bare ValueError for one), None if it is:
    auto (the cluster this machine belongs to), HOST:PORT of a head, or ray://HOST:PORT (Ray client)."""
    if address == "auto":
        return None
    host, _, port = address.removeprefix("ray://").rpartition(":")
    named = host.strip("[]") and "/" not in host  # "http://head": a URL of another scheme
    if named and port.isascii() and port.isdigit() and 0 < int(port) <= 65535:  # "²": no int
        return None
    return f"--ray {address!r} is not a Ray address: auto, HOST:PORT of the head, or ray://HOST:PORT"


def _run_on_ray(specs: list[RunSpec], ray: Any, stop: Stop) -> Iterator[tuple[RunSpec, dict[str, Any] | Exception]]:
    remote = ray.remote(num_cpus=1)(run_one)
    pending = {remote.remote(s): s for s in specs}
    while pending and not stop.asked.is_set():
        done, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_S)  # a timeout: looks up for a stop
        for ref in done:
            yield _outcome(ray, ref, pending.pop(ref))
    if pending:
        yield from _stop_on_ray(ray, pending)


def _stop_on_ray(ray: Any, pending: dict[Any, RunSpec]) -> Iterator[tuple[RunSpec, dict[str, Any] | Exception]]:
    """Cancel the runs left as a local sweep stops its own: a queued one never starts, a running one
    gets KeyboardInterrupt in its worker, whose Stop hands its `collie train` one SIGTERM and waits
    for its final checkpoint. Waits for them all, at most STOP_WAIT_S (and a margin for the news)."""
    for ref in pending:
        ray.cancel(ref, force=False)  # force would kill the worker, and Ray its trainer: no checkpoint
    ray.wait(list(pending), num_returns=len(pending), timeout=STOP_WAIT_S + 30)
    for ref, spec in pending.items():
        yield _outcome(ray, ref, spec)


def _outcome(ray: Any, ref: Any, spec: RunSpec) -> tuple[RunSpec, dict[str, Any] | Exception]:
    """(spec, its summary or why not): a run cancelled before it started is Interrupted; one that
    raised is its exception (StoppedEarly for a stopped training: Ray's error is a subclass)."""
    try:
        return spec, ray.get(ref, timeout=0)
    except ray.exceptions.TaskCancelledError:
        return spec, Interrupted("not started: the sweep was interrupted")
    except ray.exceptions.GetTimeoutError:
        return spec, StoppedEarly(f"{spec.out} did not end {STOP_WAIT_S:.0f} s after the sweep was interrupted")
    except Exception as exc:  # a failed run is reported, the others go on
        return spec, exc


# ---- `collie sweep` ------------------------------------------------------------------------------
# `collie` adds this to "unrecognized arguments" (collie/cli.py): a train flag given before --.
UNRECOGNIZED_HINT = "; flags for every `collie train` go after --, e.g. collie sweep … -- --epochs 2"
DASHED_VALUE_OPTIONS = ("--downstream-flags",)  # its value is flags: `--downstream-flags "--kind zero_shot"`
DEFAULT_TASKS = "north,range,hole_north"


class _Refusal(Exception):
    pass


class _TrainParser(argparse.ArgumentParser):
    """`collie train`'s parser, raising instead of exiting; no abbreviated flags, as collie/cli.py
    builds it (`python -m trainer.downstream`'s takes them: allow_abbrev)."""

    def __init__(self, prog: str, allow_abbrev: bool = False) -> None:
        super().__init__(prog=prog, allow_abbrev=allow_abbrev)

    def error(self, message: str) -> NoReturn:
        raise _Refusal(message)

    def exit(self, status: int = 0, message: str | None = None) -> NoReturn:  # e.g. -- --help
        raise _Refusal(message or "a flag that ends `collie train` at once (--help?) is no run's flag")


# `collie train` options the sweep sets for each run (train_argv), and what to give the sweep instead
SWEEP_OWNS = {
    "--env": "give collie sweep --env",
    "--task": "give --tasks",
    "--method": "give --methods",
    "--preset": "give collie sweep --preset",
    "--seed": "give --first-seed / --seeds",
    "--out": "give collie sweep --out, the root of the run folders",
    "--threads": "one per run, --jobs runs at a time",
    "--resume": "a rerun of the sweep resumes",
}


def owned_problem(flags: list[str]) -> str | None:
    """The train flags after -- that set what the sweep sets for each run (as `collie up
    --train-args` refuses its own), naming what to give the sweep instead."""
    owned = owned_flags(flags, SWEEP_OWNS)
    if not owned:
        return None
    options = dict.fromkeys(f.split("=")[0] for f in owned)
    instead = "; ".join(f"{option}: {SWEEP_OWNS[option]}" for option in options)
    return f"flags after -- may not set {', '.join(owned)}: collie sweep sets them for each run ({instead})"


def train_flags_problem(specs: list[RunSpec]) -> str | None:
    """What `collie train` would refuse in the runs' commands (a bad flag after --, a value out of
    range), found by parsing each method's and task's command once, before any run starts."""
    from trainer import cli as train_cli

    parser = _TrainParser(prog="collie train")
    train_cli.add_arguments(parser)
    for spec in {(s.method, s.task): s for s in specs}.values():
        try:
            train_cli.config_from_args(parser.parse_args(train_argv(spec)))
        except (_Refusal, ValueError) as exc:
            return f"collie train would refuse {spec.method} on {spec.task} ({shlex.join(spec.flags)}): {exc}"
    return None


def add_arguments(p: argparse.ArgumentParser) -> None:
    from collie.tasks import ENV_TASKS, task_names
    from trainer.envs.registry import ENV_NAMES

    # Each default is shown: together they are the full grid a bare `collie sweep` runs (the epilog).
    p.add_argument("--env", default="point", help=f"one of: {', '.join(ENV_NAMES)} (default: %(default)s)")
    p.add_argument(
        "--tasks",
        default=None,
        help=f"comma-separated, of: {', '.join(task_names())} or a --task-file's task (default: {DEFAULT_TASKS}; "
        f"{'; '.join(env + ': ' + ','.join(tasks) for env, tasks in ENV_TASKS.items())}) "
        "— with --task-file and no --tasks, the files' tasks alone",
    )
    p.add_argument(
        "--task-file",
        action="append",
        default=[],
        metavar="FILE",
        help="a task rule from a file (docs/tasks.md), one task per file: its task joins the sweep's tasks "
        "(repeat it for more files)",
    )
    p.add_argument(
        "--methods", default=",".join(METHODS), help=f"comma-separated, of: {', '.join(METHODS)} (default: %(default)s)"
    )
    p.add_argument("--seeds", type=int, default=3, help="how many seeds: FIRST … FIRST+N−1 (default: %(default)s)")
    p.add_argument("--first-seed", type=int, default=0, metavar="FIRST", help="the lowest seed (default: %(default)s)")
    p.add_argument("--preset", default="cpu", help=f"one of: {', '.join(PRESETS)} (default: %(default)s)")
    p.add_argument("--out", default="runs/sweep", help="root folder of the run folders (default: %(default)s)")
    p.add_argument(
        "--variant", default="", help="name of this ablation (folder suffix and report label): letters, digits and _"
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=os.cpu_count() or 1,
        help="runs at a time on this machine (default: its CPU count, %(default)s)",
    )
    p.add_argument("--ray", default=None, metavar="ADDRESS", help="run on the Ray cluster at ADDRESS instead")
    p.add_argument("--downstream", action="store_true", help="evaluate each finished run's downstream task")
    p.add_argument("--downstream-flags", default="", help="flags for `python -m trainer.downstream`, quoted")
    p.add_argument("--no-report", action="store_true", help="do not write OUT/report/ afterwards")
    p.add_argument(
        "--bin-rule",
        choices=BIN_RULES,
        default="corner",
        help="coverage rule of OUT/report/ (collie report --bin-rule; default: the paper's corner rule)",
    )
    p.add_argument("train_flags", nargs=argparse.REMAINDER, help="after --: flags for every `collie train`")
    tasks, seeds = len(DEFAULT_TASKS.split(",")), p.get_default("seeds")
    p.epilog = (
        f"A bare `collie sweep` runs the full grid the defaults name: {len(METHODS)} methods × {tasks} tasks × "
        f"{seeds} seeds on {p.get_default('env')} at the {p.get_default('preset')} preset, "
        f"{len(METHODS) * tasks * seeds} runs (hours on 2 cores). Flags for `collie train` go after --."
    )


def names(flag: str, given: str) -> tuple[list[str], str | None]:
    """`given`'s comma-separated names (spaces around them dropped), or the problem naming `flag`'s
    empty entry ("north,,range" would otherwise become a run of task '')."""
    listed = [n.strip() for n in given.split(",")]
    empty = [i for i, n in enumerate(listed, 1) if not n]
    if empty:
        return listed, f"{flag} {given!r}: entry {empty[0]} of {len(listed)} is empty"
    return listed, None


def file_tasks(files: list[str], env: str, layout_seed: int) -> tuple[dict[str, str], str | None]:
    """{task name: its file, absolute} for each --task-file, each loaded once for `env` (as every
    run will load it), or the first problem: a file `collie train` would refuse, one that registers
    several tasks, two files defining one name."""
    from collie.tasks.task_file import load_task_file

    found: dict[str, str] = {}
    for given in files:
        path = str(Path(given).resolve())  # runs start elsewhere (a Ray node, another cwd)
        try:
            name = load_task_file(path, None, env, layout_seed=layout_seed).name
        except ValueError as exc:  # TaskFileError: the file, the line or key, and why
            several = "; pick one with --task"  # a Python file registering several: a sweep takes one per file
            return found, f"--task-file {given}: {exc}".replace(several, "; a sweep takes one task per file")
        if name in found:
            return found, f"--task-file {given} defines task {name!r}, as --task-file {found[name]} does"
        found[name] = path
    return found, None


def chosen_tasks(given: str | None, from_files: dict[str, str], env: str) -> tuple[list[str], str | None]:
    """The sweep's tasks: --tasks (default DEFAULT_TASKS or the env's ENV_TASKS, none beside task files), then
    each file's task not named there; or the problem naming --tasks' empty entry."""
    from collie.tasks import ENV_TASKS

    if given is None and from_files:
        return list(from_files), None
    default = ",".join(ENV_TASKS.get(env, ())) or DEFAULT_TASKS
    tasks, empty = names("--tasks", default if given is None else given)  # --tasks '': refused, not the default
    return list(dict.fromkeys([*tasks, *from_files])), empty


def problem(args: argparse.Namespace, methods: list[str], tasks: list[str], from_files: dict[str, str]) -> str | None:
    """The first thing wrong with the sweep's arguments, found before any run is launched (a bad
    name would otherwise fail every run, each in its own process); None if there is none."""
    from collie.tasks import get_task, task_names
    from trainer.envs.registry import ENV_NAMES

    known = [*task_names(), *from_files]
    bad_methods, bad_tasks = [m for m in methods if m not in METHODS], [t for t in tasks if t not in known]
    if bad_methods:
        return f"unknown method(s) {', '.join(bad_methods)}; valid: {', '.join(METHODS)}"
    if args.env not in ENV_NAMES:
        return f"unknown --env {args.env!r}; valid: {', '.join(ENV_NAMES)}"
    if bad_tasks:
        return f"unknown task(s) {', '.join(bad_tasks)}; valid: {', '.join(known)} (or a task from a --task-file)"
    if args.preset not in PRESETS:
        return f"unknown --preset {args.preset!r}; valid: {', '.join(PRESETS)}"
    if any(f == "--task-file" or f.startswith("--task-file=") for f in args.train_flags):
        return (
            "--task-file goes before --: `collie sweep --task-file FILE` runs the file's task (its runs alone get it)"
        )
    owned = owned_problem([f for f in args.train_flags if f != "--"])
    if owned:
        return owned
    for task in (t for t in tasks if t not in from_files):  # one with no geometry for the env (north on car)
        try:
            get_task(task, args.env, layout_seed=args.first_seed)
        except ValueError as exc:
            return f"task {task} on --env {args.env}: {exc}"
    if args.seeds < 1:
        return "--seeds must be ≥ 1"
    if args.jobs < 1:
        return "--jobs must be ≥ 1"
    if args.first_seed < 0:
        return "--first-seed must be ≥ 0"
    if not all(c.isalnum() or c == "_" for c in args.variant):  # a folder-name part: no "/", "+" or "-"
        return f"--variant {args.variant!r}: letters, digits and _ only"
    if Path(args.out).exists() and not Path(args.out).is_dir():
        return f"--out {args.out} is a file, not a folder"
    if args.ray is not None and (wrong_ray := ray_address_problem(args.ray)):
        return wrong_ray
    try:
        downstream_flags = shlex.split(args.downstream_flags)
    except ValueError as exc:  # an unclosed quote
        return f"--downstream-flags {args.downstream_flags!r}: {exc}"
    if downstream_flags and args.downstream:  # else every run trains first, then each downstream task refuses them
        return downstream_flags_problem(args.downstream_flags, downstream_flags)
    return None


def downstream_flags_problem(given: str, flags: list[str]) -> str | None:
    """What `python -m trainer.downstream RUN FLAGS` would refuse in `flags`, split from --downstream-flags
    `given` (None if nothing)."""
    from trainer.downstream import __main__ as downstream

    parser = _TrainParser(prog="python -m trainer.downstream", allow_abbrev=True)
    downstream.add_arguments(parser)
    try:
        why = downstream.refusal(parser.parse_args(["RUN", *flags]))
    except _Refusal as exc:
        why = str(exc)
    return f"--downstream-flags {given!r}: python -m trainer.downstream would refuse them: {why}" if why else None


def check_writable(folder: Path) -> None:
    """OSError naming `folder` if no file can be made in it (a read-only file system, a full disk):
    else every run would fail in turn, a FAILED line each, before the report's write said why
    (collie/cli.py turns the error into its line)."""
    make_folder(folder)
    try:
        with tempfile.TemporaryFile(dir=folder) as f:  # a byte: a full disk makes an empty file
            f.write(b"?")
            f.flush()
    except OSError as exc:  # its name is a random file's: the folder's is the one to say
        raise OSError(exc.errno, exc.strerror, str(folder)) from None


def resumed_otherwise(spec: RunSpec) -> str | None:
    """How an unfinished run the sweep resumes from its checkpoint differs from what `spec`'s
    command would make (its epochs aside: a resume takes the command's), as made_otherwise says it;
    None if it does not or starts anew. `collie train --resume` keeps the checkpoint's config, so
    the new flags would apply to the runs begun now and not to it, said only in its .log."""
    if is_finished(spec.out) or not has_checkpoint(spec.out):
        return None
    keys, made, asked = config_change(spec, besides=("epochs",))
    return f"{recorded(spec)} ({shown_values(keys, made, asked)})" if keys else None


def say_what_finished_runs_get(specs: list[RunSpec]) -> None:
    """A line for each finished run the sweep extends to more epochs, and a warning for each that
    another configuration would not be rerun, or (an interrupted run) resumes with its own."""
    for spec in specs:
        if not is_finished(spec.out):
            resumed = resumed_otherwise(spec)
            if resumed:
                print(
                    f"warning: {spec.out} resumes from its checkpoint with {resumed}; the new flags do not "
                    "apply to it (remove it to start it anew)",
                    file=sys.stderr,
                )
            continue
        grows = extension(spec)
        differs = made_otherwise(spec)
        if grows:
            print(f"{spec.out}: finished at {grows[0]} epochs; extended to {grows[1]} (resumed from its checkpoint)")
        elif differs:
            print(f"warning: {spec.out} finished with {differs}; not rerun (remove it to rerun)", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from_files, wrong_file = file_tasks(args.task_file, args.env, args.first_seed)
    (methods, empty_method), (tasks, empty_task) = (
        names("--methods", args.methods),
        chosen_tasks(args.tasks, from_files, args.env),
    )
    methods, tasks = list(dict.fromkeys(methods)), list(dict.fromkeys(tasks))  # a name twice: one run folder
    wrong = empty_method or empty_task or wrong_file or problem(args, methods, tasks, from_files)
    if wrong:
        print(f"collie sweep: error: {wrong}", file=sys.stderr)
        return 2
    flags = tuple(f for f in args.train_flags if f != "--")
    specs = grid(
        args.out,
        args.env,
        tasks,
        methods,
        list(range(args.first_seed, args.first_seed + args.seeds)),
        from_files,
        preset=args.preset,
        variant=args.variant,
        flags=flags,
        downstream=args.downstream,
        downstream_flags=tuple(shlex.split(args.downstream_flags)),
    )
    wrong = train_flags_problem(specs)  # finished runs too: a typo is one, whether or not a run is left
    if wrong:
        print(f"collie sweep: error: {wrong}", file=sys.stderr)
        return 2
    try:  # before anything is said or made (no head: one line); before our handlers, which ray.init would replace
        if args.ray:
            connect_ray(args.ray)
    except RuntimeError as exc:
        print(f"collie sweep: error: {exc}", file=sys.stderr)
        return 2
    pending = [s for s in specs if to_train(s)]
    if pending or args.downstream or not args.no_report:  # something will be written under --out
        check_writable(Path(args.out))
    say_what_finished_runs_get(specs)
    processes = "1 local process" if args.jobs == 1 else f"{args.jobs} local processes"
    resumed = sum(has_checkpoint(s.out) for s in pending)
    print(
        f"{len(specs)} run{'' if len(specs) == 1 else 's'}, {len(specs) - len(pending)} already finished"
        f"{f', {resumed} resumed from their checkpoints' if resumed else ''}; engine: "
        f"{'ray ' + args.ray if args.ray else processes}"
    )
    failed: list[tuple[RunSpec, Exception]] = []
    stop, before = Stop(), {}
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # Ray's runs too: each is cancelled, and stops
        if signal.getsignal(sig) is not signal.SIG_IGN:  # under nohup a closed terminal stops nothing
            before[sig] = signal.signal(sig, stop.handle)
    try:
        with tqdm(total=len(specs), desc="sweep", unit="run") as bar:
            for spec, result in run_all(specs, args.jobs, args.ray, stop):
                if isinstance(result, Exception):
                    failed.append((spec, result))
                if not (stop.asked.is_set() and isinstance(result, Interrupted | StoppedEarly)):
                    bar.update(1)  # done: finished or failed, not stopped by us or never started
    except RuntimeError as exc:  # the engine itself could not start
        print(f"collie sweep: error: {exc}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
    for spec, error in failed:
        if not isinstance(error, Interrupted | StoppedEarly) or not stop.asked.is_set():
            print(f"FAILED {spec.out}: {error}", file=sys.stderr)
    if stop.asked.is_set():
        stopped = sum(isinstance(e, StoppedEarly) for _, e in failed)
        never = sum(isinstance(e, Interrupted) for _, e in failed)
        print(
            f"collie sweep: interrupted; {stopped} run(s) stopped, {never} not started; "
            "rerun the same command to resume",
            file=sys.stderr,
        )
        return 130
    if not args.no_report:
        from trainer.report import write_report

        with writing_into(Path(args.out) / "report"):
            paths = write_report([Path(args.out)], Path(args.out) / "report", bin_rule=args.bin_rule)
        print(f"report: {paths['markdown']}")
    return 1 if failed else 0
