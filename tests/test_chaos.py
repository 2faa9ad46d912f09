"""The chaos benchmark's short version (benchmarks/bench_chaos.py --short): a small oracle-labelled
run under `collie up` with ≥ 10 kill -9 spread over service, trainer, teacher and labeling UI. Every
label stored is applied once, none is duplicated, no session is asked twice, and the run finishes."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)

ROOT = Path(__file__).resolve().parents[1]


def test_short_chaos_run_loses_nothing_and_finishes(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_chaos.py"), "--short", "--out", str(tmp_path / "chaos")],
        capture_output=True,
        text=True,
        timeout=900,
    )
    result = json.loads((tmp_path / "chaos.json").read_text())["figures"]
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert result["kills_total"] >= 10 and all(n >= 2 for n in result["kills"].values()), result["kills"]
    assert result["finished"]
    assert result["lost"] == result["duplicates"] == result["sessions_re_asked"] == result["applied_not_stored"] == 0
    assert result["labels_stored"] == result["labels_applied"] == result["labels_wanted"] == result["queries_asked"]
