"""Every test runs in a scratch working directory: MuJoCo appends its warnings to MUJOCO_LOG.TXT in
the cwd (of this process and of every service or UI a test starts), never in the checkout."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest


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
