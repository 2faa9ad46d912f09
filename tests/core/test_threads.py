"""The trainer's thread policy (trainer/threads.py): one intra-op thread on small machines or for
small nets, a passive OpenMP wait, and variables set before torch starts its pool."""

import os
import subprocess
import sys

from trainer.threads import openmp_env, resolve_threads


def test_thread_count_policy():
    assert resolve_threads(0, 1024, cores=2) == 1  # ≤ 4 cores
    assert resolve_threads(0, 256, cores=16) == 1  # small nets
    assert resolve_threads(0, 1024, cores=16) == 16
    assert resolve_threads(3, 256, cores=2) == 3  # an explicit --threads wins
    assert openmp_env(1) == {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OMP_WAIT_POLICY": "PASSIVE"}


def test_variables_reach_torch_when_set_before_import():
    env = {k: v for k, v in os.environ.items() if k not in openmp_env(1)}
    code = (
        "import os; from trainer.threads import apply_openmp_env; apply_openmp_env(1); import torch; "
        "print(torch.get_num_threads(), os.environ['OMP_WAIT_POLICY'])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.split() == ["1", "PASSIVE"]


def test_collie_train_loads_torch_only_after_it_sets_the_variables():
    """`collie train` imports its command's module, then sets the variables, then imports the trainer:
    that module must not load torch (was: ResumeError's module did, so OMP_WAIT_POLICY=PASSIVE never
    reached OpenMP in a run started by hand, only in one `collie up` started)."""
    code = "import sys, collie.cli, trainer.cli; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False"]
