"""The memory ledger (trainer/memory_ledger.py): what running runs were promised and have not taken
yet counts as taken, for runs in other processes, whatever order they start in."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from trainer.memory_ledger import LEDGER_ENV, Promise, check_beside_others, process_start, promised_elsewhere
from trainer.memory_plan import GIB, NotEnoughMemory

MIB = 2**20
# a run's process, as far as the ledger sees one: it promises argv[1] bytes of argv[2] free, then
# on each line of stdin touches argv[3] MiB more, and ends when stdin closes
PROMISING = """
import sys
import numpy as np
from trainer.memory_ledger import reserve
from trainer.memory_plan import NotEnoughMemory
try:
    reserve("the replay", int(sys.argv[1]), available=int(sys.argv[2]))
    print("promised", flush=True)
except NotEnoughMemory as exc:
    print(f"refused: {exc}", flush=True)
    sys.exit(75)
held = []
for _ in sys.stdin:
    held.append(np.ones(int(sys.argv[3]) * 2**20, np.uint8))  # ones: every page touched
    print("touched", flush=True)
"""


def promising(ledger: Path, floor: int, free: int, touch_mib: int = 0) -> subprocess.Popen[str]:
    env = {**os.environ, LEDGER_ENV: str(ledger)}
    cmd = [sys.executable, "-c", PROMISING, str(floor), str(free), str(touch_mib)]
    return subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)


@pytest.fixture
def ledger(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv(LEDGER_ENV, str(tmp_path / "ledger"))
    return tmp_path / "ledger"


def test_what_a_running_run_was_promised_and_has_not_touched_is_not_free(ledger: Path) -> None:
    run = promising(ledger, 2 * GIB, 10 * GIB, touch_mib=512)
    try:
        assert run.stdout is not None and run.stdin is not None
        assert run.stdout.readline() == "promised\n"
        check_beside_others("the replay", 7 * GIB, available=10 * GIB)  # 8 GiB left: fits
        with pytest.raises(NotEnoughMemory) as caught:
            check_beside_others("the replay", 9 * GIB, available=10 * GIB)
        said = str(caught.value)
        assert said.startswith("the replay: at least 9.0 GiB, 10.0 GiB free, 2.0 GiB of it promised to running runs")
        assert said.endswith(f"(pid {run.pid})") and caught.value.holders == (run.pid,)
        assert caught.value.fits_alone  # alone it would fit: a sweep waits, and starts it again
        with pytest.raises(NotEnoughMemory, match=r"1\.5 GiB free, 1\.5 GiB of it promised to running runs"):
            check_beside_others("the replay", GIB, available=3 * GIB // 2)  # promised 2 GiB: said as at most all
        with pytest.raises(NotEnoughMemory, match=r"^the replay: at least 11\.0 GiB, 10\.0 GiB free$"):
            check_beside_others("the replay", 11 * GIB, available=10 * GIB)  # not even alone: no word of others
        before = promised_elsewhere(ledger)[0]
        assert 2 * GIB - 64 * MIB < before <= 2 * GIB  # what the process took since it promised, a little
        run.stdin.write("\n")
        run.stdin.flush()
        assert run.stdout.readline() == "touched\n"
        taken = before - promised_elsewhere(ledger)[0]
        assert 480 * MIB < taken < 560 * MIB  # the 512 MiB it touched now count as used, not promised
        run.stdin.close()
        assert run.wait(timeout=30) == 0
        assert promised_elsewhere(ledger) == (0, []) and list(ledger.glob("*.json")) == []  # its entry went
    finally:
        run.kill()


def test_of_two_runs_checked_at_once_the_second_counts_the_first(ledger: Path) -> None:
    """Each fits alone (6 of 10 GiB), not both: the lock lets one promise before the other checks."""
    runs = [promising(ledger, 6 * GIB, 10 * GIB) for _ in range(2)]
    try:
        said = sorted(run.stdout.readline() for run in runs if run.stdout is not None)
        assert said[0] == "promised\n" and said[1].startswith("refused: the replay: at least 6.0 GiB, 10.0 GiB free")
    finally:
        for run in runs:
            run.kill()


def test_a_promise_whose_process_is_gone_or_was_another_s_counts_nothing(ledger: Path) -> None:
    ledger.mkdir()
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    parent = os.getppid()  # alive, but started at another time than the promise says: its pid was reused
    started = process_start(parent)
    assert started is not None
    for pid, when in ((int(gone.stdout), 1), (parent, started + 1)):
        promise = Promise(pid=pid, started=when, floor=4 * GIB, anonymous=0)
        (ledger / f"{pid}.json").write_text(json.dumps(promise.__dict__))
    assert promised_elsewhere(ledger) == (0, [])
    assert list(ledger.glob("*.json")) == []  # neither is read again
    (ledger / f"{parent}.json").write_text(json.dumps(Promise(parent, started, 4 * GIB, 64 * GIB).__dict__))
    assert promised_elsewhere(ledger) == (4 * GIB, [parent])  # the same process, as promised: counted


def test_files_that_are_no_promise_are_passed_over_and_kept(ledger: Path) -> None:
    """$COLLIE_MEMORY_LEDGER may name a folder that holds other files: none is read as a promise
    or removed, and a promise of the wrong kind of numbers is no traceback."""
    ledger.mkdir()
    parent = os.getppid()
    others = {
        "package.json": '{"name": "x"}',
        f"{parent}.json.partial": "{",
        "12.json": '{"pid": 9, "sta',  # half a file
        f"{parent}.json": json.dumps({"pid": parent, "started": process_start(parent), "floor": "1", "anonymous": 0}),
    }
    for name, text in others.items():
        (ledger / name).write_text(text)
    check_beside_others("the replay", GIB, available=2 * GIB)
    assert promised_elsewhere(ledger) == (0, [])
    assert {p.name: p.read_text() for p in ledger.iterdir() if p.name != ".lock"} == others


@pytest.mark.parametrize("whose", ["another user's", "writable by the group"])
def test_a_ledger_folder_others_may_write_in_is_not_used(ledger: Path, whose: str) -> None:
    """A folder at the ledger's name that another user made (or may write in) could hold a FIFO for
    its lock, links for its files, or promises that block every run: it is neither read nor written,
    and the run is checked alone."""
    ledger.mkdir(mode=0o700)
    parent = os.getppid()
    promise = Promise(pid=parent, started=process_start(parent) or 0, floor=4 * GIB, anonymous=64 * GIB)
    (ledger / f"{parent}.json").write_text(json.dumps(promise.__dict__))
    if whose == "another user's":
        if os.getuid() != 0:
            pytest.skip("only root can give a folder to another user")
        os.chown(ledger, 65534, 65534)
    else:
        ledger.chmod(0o770)
    run = promising(ledger, 2 * GIB, 3 * GIB)  # with the promise counted it would not fit
    assert run.stdout is not None and run.stdout.readline() == "promised\n"
    run.kill()
    assert sorted(p.name for p in ledger.iterdir()) == [f"{parent}.json"]  # no lock made, no entry written
