"""Whether `--fast-ops` pays on this machine: its two kernels timed against torch's, once per host.

The fast ops (trainer/networks.py: tanh as 2σ(2x) − 1, the twin Q's one-output layer as a
multiply-and-sum) compute the same functions as torch's tanh and `bmm`. Which is faster depends on
the CPU and on the kernels torch picks for it, and the CPU's capability alone does not tell: with
torch's AVX-512 kernels the fast ops were slower on an Intel Xeon host and 1.8× and 3.6× faster
on an AMD EPYC host (docs/results.md). So the default is measured: the first run on a host times
both forms, forward and backward, one thread, batch 256, interleaved (about 0.1 s), and keeps the
answer in CACHE, keyed by the CPU's model, torch's capability and torch's version. Every later run
on that host reads it, so a seed's run does not change with a timing; runs started together (a
sweep) wait on one lock for the first one's answer. Where CACHE cannot be written the run measures
for itself. GPUs: off, unmeasured (tanh is one kernel there, 2σ(2x) − 1 three).

CACHE is $COLLIE_CACHE_DIR/fast_ops.json, else $XDG_CACHE_HOME/collie/…, else ~/.cache/collie/….
Delete it to measure again."""

from __future__ import annotations

import contextlib
import fcntl
import functools
import json
import os
import statistics
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import torch
from pydantic import BaseModel, ValidationError

from collie.whole_files import write_whole
from trainer.networks import EnsembleLinear, Tanh

CACHE_ENV = "COLLIE_CACHE_DIR"


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
    one). Where CACHE cannot be read or written (no home, a read-only one): this run's own measurement."""
    key = host_key()
    try:
        with locked(cache_file()) as path:
            entries = read_entries(path)
            if key not in entries:
                entries[key] = measure_choice()
                with contextlib.suppress(OSError):
                    write_entries(path, entries)
            return entries[key]
    except OSError:
        return measure_choice()


def host_key() -> str:
    """What decides the kernels' speeds: the CPU, the code path torch picks for it, torch's version."""
    model = "unknown CPU"
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("model name", "Model", "Hardware")) and ":" in line:
                model = line.split(":", 1)[1].strip()
                break
    return f"{model} | {torch.backends.cpu.get_cpu_capability()} | torch {torch.__version__}"


def cache_file() -> Path:
    given = os.environ.get(CACHE_ENV)
    if given:
        folder = Path(given)
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        folder = (Path(xdg) if xdg else Path.home() / ".cache") / "collie"
    folder.mkdir(parents=True, exist_ok=True)
    return folder / "fast_ops.json"


@contextlib.contextmanager
def locked(path: Path) -> Iterator[Path]:
    """`path`, with its lock file held: one process measures while the others wait for its answer."""
    with open(path.with_name(path.name + ".lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield path


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
        with torch.random.fork_rng(devices=[]):
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
