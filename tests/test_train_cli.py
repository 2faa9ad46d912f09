"""`collie train` on ordinary mistakes: one line `collie train: error: …` naming the flag or file, exit 2,
and no run folder overwritten or created by a refused command."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)

TRAIN = [sys.executable, "-m", "collie.cli", "train", "--env", "point", "--preset", "smoke", "--no-progress"]


def train(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=timeout)


def refused(proc: subprocess.CompletedProcess[str], *words: str) -> str:
    """The one-line error, checked: exit 2, no traceback, every word in it."""
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith("collie train: error: "), proc.stderr
    for word in words:
        assert word in line, line
    return line


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real 2-epoch smoke run (checkpoint, replay chunk, metrics, summary)."""
    out = tmp_path_factory.mktemp("finished") / "run"
    proc = train("--epochs", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


@pytest.fixture
def run_copy(finished: Path, tmp_path: Path) -> Path:
    """A copy of the finished run that a test may damage."""
    return Path(shutil.copytree(finished, tmp_path / "run"))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_an_existing_run_is_not_overwritten_without_resume(run_copy: Path) -> None:
    before = {p.name: digest(p) for p in run_copy.iterdir() if p.is_file()}
    refused(train("--epochs", "1", "--out", str(run_copy)), "already holds a run", "--resume", "--out")
    assert {p.name: digest(p) for p in run_copy.iterdir() if p.is_file()} == before
