"""Every test runs in a scratch working directory: MuJoCo appends its warnings to MUJOCO_LOG.TXT in
the cwd (of this process and of every service or UI a test starts), never in the checkout. The
processes tests start take Ctrl-C and hang-ups, however the suite itself was started."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator

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


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Files marked `slow` first (a stable sort keeps each file's order): `make test` runs the files
    on two workers (`-n 2 --dist loadfile`), and a long file handed out last would run alone while
    the other worker idles."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
