"""`--fast-ops`'s default: measured once per host, kept in the cache, the same for every later run."""

from __future__ import annotations

import fcntl
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from trainer import fast_ops
from trainer.fast_ops import cpu_choice, fast_ops_pay, host_key


@pytest.fixture
def own_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A cache folder of the test's own, and no answer remembered in this process before or after."""
    monkeypatch.setenv(fast_ops.CACHE_ENV, str(tmp_path))
    cpu_choice.cache_clear()
    yield tmp_path / "fast_ops.json"
    cpu_choice.cache_clear()


def entries(path: Path) -> dict:
    return json.loads(path.read_text())


def test_the_first_run_on_a_host_measures_and_later_runs_read_its_answer(own_cache: Path) -> None:
    on = fast_ops_pay(torch.device("cpu"))
    entry = entries(own_cache)[host_key()]
    times = entry["measured"]
    assert entry["fast_ops"] is on
    assert all(times[k] > 0 for k in ("tanh_us", "fast_tanh_us", "bmm_us", "fast_one_output_us"))
    assert on is (times["fast_tanh_us"] + times["fast_one_output_us"] < times["tanh_us"] + times["bmm_us"])
    # a later run takes the cached answer, not a new timing: flipped by hand, it is what a run gets
    own_cache.write_text(json.dumps({host_key(): {**entry, "fast_ops": not on}}))
    cpu_choice.cache_clear()
    assert fast_ops_pay(torch.device("cpu")) is (not on)


def test_a_gpu_is_off_without_a_measurement(own_cache: Path) -> None:
    assert fast_ops_pay(torch.device("cuda")) is False and fast_ops_pay(torch.device("mps")) is False
    assert not own_cache.exists()


@pytest.mark.parametrize("damage", ["{not json", "[1, 2]", "entry"])
def test_a_damaged_cache_is_measured_again_and_other_hosts_are_kept(own_cache: Path, damage: str) -> None:
    other = {"other CPU | AVX2 | torch 0": {"fast_ops": True, "at": "then", "measured": {
        "hidden": 256, "tanh_us": 2.0, "fast_tanh_us": 1.0, "bmm_us": 2.0, "fast_one_output_us": 1.0}}}  # fmt: skip
    own_cache.write_text(json.dumps({**other, host_key(): {"fast_ops": "maybe"}}) if damage == "entry" else damage)
    on = fast_ops_pay(torch.device("cpu"))
    saved = entries(own_cache)
    assert saved[host_key()]["fast_ops"] is on
    if damage == "entry":  # only the unreadable entry was replaced
        assert saved["other CPU | AVX2 | torch 0"] == other["other CPU | AVX2 | torch 0"]


def counted_measurements(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    calls: list[int] = []
    measure = fast_ops.measure_choice

    def counted() -> fast_ops.HostChoice:
        calls.append(1)
        return measure()

    monkeypatch.setattr(fast_ops, "measure_choice", counted)
    return calls


def test_without_a_home_folder_the_run_measures_for_itself_and_says_so(own_cache, monkeypatch, capsys) -> None:
    """Was: Path.home() raised RuntimeError (HOME unset, no passwd entry), which escaped as a traceback."""
    monkeypatch.delenv(fast_ops.CACHE_ENV)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)

    def no_home() -> Path:
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", no_home)
    calls = counted_measurements(monkeypatch)
    assert isinstance(fast_ops_pay(torch.device("cpu")), bool) and len(calls) == 1
    assert "--fast-ops measured for this run alone: no cache folder (Could not determine" in capsys.readouterr().err


def test_a_cache_that_cannot_be_written_is_measured_and_said(own_cache, monkeypatch, capsys) -> None:
    own_cache.mkdir()  # fast_ops.json is a folder: neither read nor replaced
    calls = counted_measurements(monkeypatch)
    assert isinstance(fast_ops_pay(torch.device("cpu")), bool) and len(calls) == 1
    assert f"this run's --fast-ops measurement is not kept: {own_cache} cannot be written" in capsys.readouterr().err
    assert own_cache.is_dir() and not any(own_cache.iterdir())


def test_a_cache_whose_lock_cannot_be_opened_is_still_read(own_cache, monkeypatch, capsys) -> None:
    """Was: any failure of the lock measured anew, so a readable answer was ignored and two runs of
    one seed could choose differently."""
    fast_ops_pay(torch.device("cpu"))
    entry = entries(own_cache)[host_key()]
    own_cache.write_text(json.dumps({host_key(): {**entry, "fast_ops": not entry["fast_ops"]}}))
    lock = own_cache.with_name("fast_ops.json.lock")
    lock.unlink()
    lock.symlink_to(own_cache.parent / "no such folder" / "lock")  # neither made nor opened
    cpu_choice.cache_clear()
    calls = counted_measurements(monkeypatch)
    assert fast_ops_pay(torch.device("cpu")) is (not entry["fast_ops"]) and not calls
    assert f"{lock} cannot be locked" in capsys.readouterr().err


def test_a_lock_held_too_long_is_passed_by(own_cache, monkeypatch, capsys) -> None:
    """A run stopped (Ctrl-Z) while it measured holds the lock: the next run waits LOCK_WAIT_S, not forever."""
    monkeypatch.setattr(fast_ops, "LOCK_WAIT_S", 0.3)
    lock = own_cache.with_name("fast_ops.json.lock")
    with open(lock, "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        start = time.monotonic()
        assert isinstance(fast_ops_pay(torch.device("cpu")), bool)
    assert time.monotonic() - start >= 0.3
    assert f"{lock} is held for more than 0.3 s" in capsys.readouterr().err
    assert host_key() in entries(own_cache)


def test_a_measurement_restores_torchs_threads(own_cache) -> None:
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        with torch.no_grad():  # a caller's no_grad does not stop its backward passes
            assert fast_ops.measure(64, repeats=2, blocks=1).tanh_us > 0
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_runs_started_together_on_a_new_host_share_one_measurement(tmp_path: Path) -> None:
    """A sweep's runs start at once: one measures, the others wait for its answer on the lock, so
    every run of the sweep makes the same choice (two timings could differ on a host near 1×).
    The three processes are held until all have imported torch, then asked at the same instant."""
    go = tmp_path / "go"
    code = (
        "import json, os, pathlib, sys, time; from trainer.fast_ops import cpu_choice\n"
        "pathlib.Path(sys.argv[1]).touch()\n"
        "while not os.path.exists(sys.argv[2]): time.sleep(0.005)\n"
        "print(cpu_choice().model_dump_json())"
    )
    env = {"PATH": "/usr/bin:/bin", fast_ops.CACHE_ENV: str(tmp_path / "cache"), "OMP_NUM_THREADS": "1"}
    ready = [tmp_path / f"ready{i}" for i in range(3)]
    procs = [
        subprocess.Popen([sys.executable, "-c", code, str(r), str(go)], env=env, stdout=subprocess.PIPE, text=True)
        for r in ready
    ]
    deadline = time.monotonic() + 120
    while not all(r.exists() for r in ready) and time.monotonic() < deadline:
        time.sleep(0.01)
    go.touch()
    answers = [json.loads(p.communicate(timeout=120)[0]) for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert answers[1] == answers[0] and answers[2] == answers[0]  # the same timing, to the µs and second
    assert list(entries(tmp_path / "cache" / "fast_ops.json")) == [host_key()]


def test_a_measurement_leaves_torchs_random_state_as_it_was(own_cache: Path) -> None:
    """Was: the first run on a host drew its timing inputs from torch's seeded generator, so it
    initialised its networks unlike every later run of the same seed, which read the cache."""
    torch.manual_seed(7)
    fast_ops_pay(torch.device("cpu"))  # measures: the cache is new
    after = torch.rand(3)
    torch.manual_seed(7)
    assert torch.equal(torch.rand(3), after)


def test_the_host_key_tells_cpus_apart_on_x86_and_on_arm() -> None:
    """A home folder shared by a lab's machines holds one entry per kind of CPU: an ARM core names
    itself by implementer and part, not "model name"."""
    x86 = (
        "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 7763\nflags\t: avx2\n\n"
        "processor\t: 1\nmodel name\t: AMD EPYC 7763\n"
    )
    graviton2 = "processor\t: 0\nBogoMIPS\t: 243.75\nCPU implementer\t: 0x41\nCPU part\t: 0xd0c\n"
    graviton3 = "processor\t: 0\nBogoMIPS\t: 2100.00\nCPU implementer\t: 0x41\nCPU part\t: 0xd40\n"
    assert fast_ops.cpu_model(x86) == "AMD EPYC 7763"
    assert fast_ops.cpu_model(graviton2) == "0x41 0xd0c" != fast_ops.cpu_model(graviton3)
    assert fast_ops.cpu_model("processor\t: 0\n") == "unknown CPU"
    assert host_key().startswith(fast_ops.cpu_model(Path("/proc/cpuinfo").read_text()) + " | ")
