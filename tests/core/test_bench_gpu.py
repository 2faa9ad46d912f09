"""`make bench-gpu` without a GPU says so and succeeds; its code path runs on the CPU and writes
runs/bench/gpu.json."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from trainer.config import make_config

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_gpu.py"


def bench(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLLIE_BENCH_DIR": str(tmp_path), "PYTHONPATH": str(BENCH.parents[1])}
    return subprocess.run([sys.executable, str(BENCH), *args], capture_output=True, text=True, env=env, timeout=600)


@pytest.mark.skipif(torch.cuda.is_available(), reason="a CUDA device is present")
def test_without_cuda_it_says_so_and_exits_0(tmp_path):
    proc = bench(tmp_path)
    built = f"built for CUDA {torch.version.cuda}" if torch.version.cuda else "built without CUDA"
    assert proc.returncode == 0 and proc.stdout.strip() == f"no CUDA device (torch {torch.__version__} {built})"
    assert not (tmp_path / "gpu.json").exists()
    named = bench(tmp_path, "--device", "cuda:1")  # a GPU named by number: the same (was a traceback)
    assert named.returncode == 0 and named.stdout.startswith("no CUDA device ("), named.stderr[-2000:]


def test_its_code_path_runs_on_the_cpu(tmp_path):
    proc = bench(tmp_path, "--device", "cpu", "--preset", "smoke", "--epochs", "1", "--envs", "ant")
    assert proc.returncode == 0, proc.stderr[-2000:]
    written = json.loads((tmp_path / "gpu.json").read_text())
    figures, meta = written["figures"]["ant"], written["meta"]
    assert meta["cores"] == os.cpu_count() and meta["torch_cpu_capability"] in ("DEFAULT", "AVX2", "AVX512")
    assert figures["updates_per_s"] > 0 and figures["env_steps_per_s"] > 0 and figures["projected_hours"] > 0
    cfg = make_config("smoke", "ant")  # COLLIE's update with the whole label budget, by default
    assert (
        written["figures"]["method"] == "collie"
        and figures["labelled_states"] == cfg.total_queries * cfg.segment_length
    )
    assert written["settings"] == {"device": "cpu", "preset": "smoke", "method": "collie", "epochs": 1}


def test_a_figure_that_is_not_finite_is_written_as_strict_json_null(tmp_path, monkeypatch):
    """`compile_break_even_steps_<h>` is inf when compiling never pays: JSON has no Infinity."""
    monkeypatch.syspath_prepend(str(BENCH.parent))
    monkeypatch.setenv("COLLIE_BENCH_DIR", str(tmp_path))
    import numpy as np
    from record import record

    figures = {"never": float("inf"), "nothing": [float("nan"), np.float32(0.5)], "n": np.int64(3)}
    path = record("t", figures, {"steps": 3, "out": tmp_path}, tmp_path)
    text = path.read_text()
    assert "Infinity" not in text and "NaN" not in text
    written = json.loads(text)
    assert written["figures"] == {"never": None, "nothing": [None, 0.5], "n": 3} and isinstance(
        written["figures"]["n"], int
    )
    assert written["settings"] == {"steps": 3, "out": str(tmp_path)}
