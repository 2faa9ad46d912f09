"""`--fast-ops`'s default: measured once per host, kept in the cache, the same for every later run."""

from __future__ import annotations

import json
import subprocess
import sys
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


def test_where_the_cache_cannot_be_made_the_run_measures_for_itself(tmp_path: Path, monkeypatch) -> None:
    blocker = tmp_path / "a file"
    blocker.write_text("")
    monkeypatch.setenv(fast_ops.CACHE_ENV, str(blocker / "cache"))  # a folder under a file: OSError
    cpu_choice.cache_clear()
    try:
        assert isinstance(fast_ops_pay(torch.device("cpu")), bool)
    finally:
        cpu_choice.cache_clear()
    assert not (blocker.parent / "cache").exists()


def test_runs_started_together_on_a_new_host_share_one_measurement(tmp_path: Path) -> None:
    """A sweep's runs start at once: one measures, the others wait for its answer on the lock, so
    every run of the sweep makes the same choice (two timings could differ on a host near 1×)."""
    code = "import json; from trainer.fast_ops import cpu_choice; print(cpu_choice().model_dump_json())"
    env = {"PATH": "/usr/bin:/bin", fast_ops.CACHE_ENV: str(tmp_path), "OMP_NUM_THREADS": "1"}
    procs = [
        subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True) for _ in range(3)
    ]
    answers = [json.loads(p.communicate(timeout=120)[0]) for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert answers[1] == answers[0] and answers[2] == answers[0]  # the same timing, to the µs and second
    assert list(entries(tmp_path / "fast_ops.json")) == [host_key()]


def test_a_measurement_leaves_torchs_random_state_as_it_was(own_cache: Path) -> None:
    """Was: the first run on a host drew its timing inputs from torch's seeded generator, so it
    initialised its networks unlike every later run of the same seed, which read the cache."""
    torch.manual_seed(7)
    fast_ops_pay(torch.device("cpu"))  # measures: the cache is new
    after = torch.rand(3)
    torch.manual_seed(7)
    assert torch.equal(torch.rand(3), after)
