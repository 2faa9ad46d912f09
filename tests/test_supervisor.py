"""The supervisor of `collie up`'s parts on a disk it cannot write (full): the parts still run."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from collie.supervisor import Supervisor


def test_a_children_file_that_cannot_be_written_is_a_warning_not_the_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "children.json").mkdir()  # renaming a file over a folder fails, as a write on a full disk does
    stack = Supervisor(tmp_path)
    try:
        proc = stack.start("helpful", lambda: ["--help"], dict(os.environ))
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert proc.returncode == 0
    finally:
        stack.stop()
    assert f"collie up: warning: cannot write {tmp_path / 'children.json'}: " in capsys.readouterr().err
    assert not (tmp_path / "children.json.partial").exists()
