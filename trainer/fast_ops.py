"""Whether `--fast-ops` pays on this machine: its two kernels timed against torch's, once per host.

The fast ops (trainer/networks.py: tanh as 2σ(2x) − 1, the twin Q's one-output layer as a
multiply-and-sum) compute the same functions as torch's tanh and `bmm`. Which is faster depends on
the CPU and on the kernels torch picks for it, and the CPU's capability alone does not tell: with
torch's AVX-512 kernels the fast ops were slower on an Intel Xeon host and 1.8× and 3.6× faster
on an AMD EPYC host (docs/results.md). So the default is measured: the first run on a host times
both forms, forward and backward, one thread, batch 256, interleaved (under half a second; `make
bench-update`: `fast_ops_measure_s`), and keeps the answer in CACHE, keyed by the CPU's model,
torch's capability and torch's version. Every later run
on that host reads it, so a seed's run does not change with a timing; runs started together (a
sweep) wait on one lock for the first one's answer. Where CACHE cannot be written the run measures
for itself and says so. GPUs: off, unmeasured (tanh is one kernel there, 2σ(2x) − 1 three).

CACHE is $COLLIE_CACHE_DIR/fast_ops.json, else $XDG_CACHE_HOME/collie/…, else ~/.cache/collie/….
Delete it to measure again."""

from __future__ import annotations

import contextlib
import functools
import json
import os
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import torch
from pydantic import BaseModel, ValidationError

from collie.processes import LockHeld, hold_lock
from collie.whole_files import write_whole
from trainer.networks import EnsembleLinear, Tanh

CACHE_ENV = "COLLIE_CACHE_DIR"
LOCK_WAIT_S = 30.0  # a measurement takes under a second; longer is a stopped or hung process


class KernelTimes(BaseModel):
    """µs of one forward and backward pass at `hidden` wide, batch 256, one thread."""

    hidden: int
    tanh_us: float  # torch.tanh
    fast_tanh_us: float  # 2σ(2x) − 1
    bmm_us: float  # the twin Q's one-output layer by bmm
    fast_one_output_us: float  # by multiply-and-sum

    @property
    def tanh_speedup(self) -> float:
        return self.tanh_us / self.fast_tanh_us

    @property
    def one_output_speedup(self) -> float:
        return self.bmm_us / self.fast_one_output_us

    @property
    def pays(self) -> bool:
        """The two fast forms together take less time than torch's two."""
        return self.fast_tanh_us + self.fast_one_output_us < self.tanh_us + self.bmm_us


class HostChoice(BaseModel):
    """One host's entry in CACHE."""

    fast_ops: bool
    measured: KernelTimes
    at: str  # when, UTC


def fast_ops_pay(device: torch.device) -> bool:
    """`--fast-ops`'s default on `device`: on a CPU, this host's measured answer; elsewhere off."""
    return device.type == "cpu" and cpu_choice().fast_ops


@functools.cache
def cpu_choice() -> HostChoice:
    """This host's entry in CACHE, measured and written there first if it has none (or a damaged
    one). Where the lock cannot be had, CACHE is read without it; where CACHE cannot be read or
    written (no home, another user's folder), this run measures for itself and says so."""
    key = host_key()
    try:
        path = cache_file()
    except (OSError, RuntimeError) as exc:  # RuntimeError: no home folder to be found
        warn(f"--fast-ops measured for this run alone: no cache folder ({exc})")
        return measure_choice()
    with locked(path):
        entries = read_entries(path)
        if key in entries:
            return entries[key]
        entries[key] = measure_choice()
        try:
            write_entries(path, entries)
        except OSError as exc:
            warn(f"this run's --fast-ops measurement is not kept: {path} cannot be written ({exc})")
        return entries[key]


def warn(said: str) -> None:
    print(f"collie: warning: {said}", file=sys.stderr)


def host_key() -> str:
    """What decides the kernels' speeds: the CPU, the code path torch picks for it, torch's version."""
    try:
        model = cpu_model(Path("/proc/cpuinfo").read_text())
    except OSError:
        model = "unknown CPU"
    return f"{model} | {torch.backends.cpu.get_cpu_capability()} | torch {torch.__version__}"


# An x86 CPU names itself in "model name"; an ARM one often only by its implementer and part
# numbers: a home folder shared by a lab's machines must not give two kinds of CPU one entry.
CPU_FIELDS = ("model name", "CPU implementer", "CPU part", "Hardware", "Model")


def cpu_model(cpuinfo: str) -> str:
    """The first core's CPU_FIELDS in /proc/cpuinfo's text, joined; "unknown CPU" if none."""
    found: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        name, colon, value = line.partition(":")
        if colon and name.strip() in CPU_FIELDS:
            found.setdefault(name.strip(), value.strip())
    return " ".join(found[f] for f in CPU_FIELDS if f in found) or "unknown CPU"


def cache_file() -> Path:
    """CACHE, its folder made if absent. A relative $XDG_CACHE_HOME is ignored, as XDG says."""
    given = os.environ.get(CACHE_ENV)
    folder = Path(given) if given else user_cache() / "collie"
    folder.mkdir(parents=True, exist_ok=True)
    return folder / "fast_ops.json"


def user_cache() -> Path:
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    return Path(xdg) if os.path.isabs(xdg) else Path.home() / ".cache"


@contextlib.contextmanager
def locked(path: Path) -> Iterator[None]:
    """Held: CACHE's lock, so that one process measures while the others wait for its answer. Not
    held, with a warning, where the lock file cannot be opened or locked (another user's, a file
    system without locks) or another process holds it past LOCK_WAIT_S (one stopped mid-measurement)."""
    lock, deadline = path.with_name(path.name + ".lock"), time.monotonic() + LOCK_WAIT_S
    while True:
        try:
            fd = hold_lock(lock)
            break
        except LockHeld:
            if time.monotonic() > deadline:
                warn(f"{lock} is held for more than {LOCK_WAIT_S:g} s: the --fast-ops cache is read without its lock")
                yield
                return
            time.sleep(0.02)
        except OSError as exc:
            warn(f"{lock} cannot be locked ({exc}): the --fast-ops cache is read without its lock")
            yield
            return
    try:
        yield
    finally:
        os.close(fd)


def read_entries(path: Path) -> dict[str, HostChoice]:
    """CACHE's entries; a missing or damaged file (or entry) reads as none, to be measured again."""
    try:
        raw = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    entries: dict[str, HostChoice] = {}
    for key, value in raw.items() if isinstance(raw, dict) else ():
        with contextlib.suppress(ValidationError):
            entries[key] = HostChoice.model_validate(value)
    return entries


def write_entries(path: Path, entries: dict[str, HostChoice]) -> None:
    text = json.dumps({k: v.model_dump() for k, v in entries.items()}, indent=1) + "\n"
    write_whole(path, lambda f: f.write(text.encode()))


def measure_choice() -> HostChoice:
    times = measure(256)
    return HostChoice(fast_ops=times.pays, measured=times, at=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))


def measure(hidden: int, repeats: int = 20, blocks: int = 5) -> KernelTimes:
    """Both forms of both ops at `hidden` wide, one thread: the median of `blocks` blocks of
    `repeats` passes each, the four interleaved block by block so that a busy moment slows all four.
    Torch's random state is left as it was: a run that measures draws what one that reads CACHE draws."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng(devices=[]), torch.enable_grad():  # a caller's no_grad would stop backward
            return timed_passes(hidden, repeats, blocks)
    finally:
        torch.set_num_threads(threads)


def timed_passes(hidden: int, repeats: int, blocks: int) -> KernelTimes:
    """The median µs of each pass, as `measure` says."""
    x = torch.randn(256, hidden, requires_grad=True)
    features = torch.randn(2, 256, hidden, requires_grad=True)
    passes = {
        "tanh_us": fwd_bwd(torch.nn.Tanh(), x),
        "fast_tanh_us": fwd_bwd(Tanh(), x),
        "bmm_us": fwd_bwd(EnsembleLinear(2, hidden, 1, fast=False), features),
        "fast_one_output_us": fwd_bwd(EnsembleLinear(2, hidden, 1, fast=True), features),
    }
    for once in passes.values():  # warm: first calls allocate
        once()
    runs: dict[str, list[float]] = {k: [] for k in passes}
    for _ in range(blocks):
        for k, once in passes.items():
            start = time.perf_counter()
            for _ in range(repeats):
                once()
            runs[k].append(1e6 * (time.perf_counter() - start) / repeats)
    return KernelTimes(hidden=hidden, **{k: statistics.median(v) for k, v in runs.items()})


def fwd_bwd(module: torch.nn.Module, x: torch.Tensor) -> Callable[[], None]:
    grad = torch.randn_like(module(x))

    def once() -> None:
        x.grad = None
        module(x).backward(grad)

    return once
