"""Every test runs in a scratch working directory: MuJoCo appends its warnings to MUJOCO_LOG.TXT in
the cwd (of this process and of every service or UI a test starts), never in the checkout. The
processes tests start take Ctrl-C and hang-ups, however the suite itself was started."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest


def pytest_configure(config: pytest.Config) -> None:
    # A suite started in the background by a script (`make test &`: SIGINT ignored) or under nohup
    # (SIGHUP ignored) would hand those dispositions to every process it starts, and the tests that
    # Ctrl-C or hang up a child would fail. A handler that does nothing keeps them ignored here and,
    # as every handler is, is reset to the default in a child at exec.
    for sig in (signal.SIGINT, signal.SIGHUP):
        if signal.getsignal(sig) is signal.SIG_IGN:
            signal.signal(sig, lambda _signum, _frame: None)


@pytest.fixture(autouse=True, scope="session")
def scratch_cwd(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    before = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("cwd"))
    try:
        yield
    finally:
        os.chdir(before)


@pytest.fixture(autouse=True, scope="session")
def own_machine_state(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """The runs tests start promise their memory in the session's own ledger
    (trainer/memory_ledger.py), not in the machine's: a run of the user's beside the suite is not
    counted by the tests, nor theirs by it. And they keep this host's `--fast-ops` measurement in
    the session's own cache (trainer/fast_ops.py), not the user's."""
    made = {"COLLIE_MEMORY_LEDGER": "memory-ledger", "COLLIE_CACHE_DIR": "cache"}
    before = {k: os.environ.get(k) for k in made}
    os.environ.update({k: str(tmp_path_factory.mktemp(name)) for k, name in made.items()})
    try:
        yield
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


# The longest files, longest first (worker-seconds of a quiet `make test` here on 2026-12-07: 135, 118,
# 110, 103, 93, 74, 59, 54): handed out first, none of them is left to run alone at the end.
LONGEST_FILES = (
    "test_train_cli.py",
    "test_trainer_crash.py",
    "test_up_hardening.py",
    "ui/test_labeler_day.py",
    "ui/test_labeling_ui.py",
    "test_chaos.py",
    "core/test_training.py",
    "baselines/test_sweep_ray.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest files first, then the other files marked `slow` (a stable sort keeps each file's
    order): `make test` runs the files on two workers (`-n 2 --dist loadfile`), and a long file
    handed out last would run alone while the other worker idles. (xdist hands files out in this
    order only with `--no-loadscope-reorder`; by default it sorts them by their number of tests.)"""
    tests = Path(__file__).parent

    def rank(item: pytest.Item) -> tuple[int, bool]:
        name = item.path.relative_to(tests).as_posix() if item.path.is_relative_to(tests) else ""
        longest = LONGEST_FILES.index(name) if name in LONGEST_FILES else len(LONGEST_FILES)
        return longest, item.get_closest_marker("slow") is None

    items.sort(key=rank)
