"""How the `collie` command ends (collie/cli.py's `entry`): with `main`'s exit code, and with the
objects still alive moved out of the collector's reach, so that Python's shutdown does not walk
the whole of torch before the OS frees it."""

import subprocess
import sys
from importlib.metadata import entry_points, version
from pathlib import Path

import pytest

# Runs `entry` with ARGV and, at exit (after `entry` returned or raised), says how many objects the
# collector has been told to leave alone.
PROBE = """
import atexit, gc, sys
atexit.register(lambda: sys.stderr.write(f"\\nfrozen {gc.get_freeze_count()}\\n"))
sys.argv = ["collie", *sys.argv[1:]]
from collie.cli import entry
entry()
"""


def test_the_installed_collie_command_runs_entry() -> None:
    (script,) = entry_points(group="console_scripts", name="collie")
    assert script.value == "collie.cli:entry"


@pytest.mark.parametrize(
    ("argv", "code", "said"),
    [
        (["export", "--db", "{tmp}/absent.db", "--run", "1"], 2, "absent.db does not exist"),  # a command's own return
        (["export", "--help"], 0, "usage: collie export"),  # argparse's SystemExit inside main
    ],
)
def test_entry_exits_with_main_s_code_and_the_heap_frozen(tmp_path: Path, argv, code, said) -> None:
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    done = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, timeout=60)
    assert done.returncode == code, done.stderr
    assert said in done.stdout + done.stderr
    frozen = int(done.stderr.rsplit("frozen ", 1)[1])
    assert frozen > 1000, done.stderr  # every object of the imports, not a handful


def test_version_names_the_installed_package() -> None:
    """Was: "the following arguments are required: COMMAND", exit 2."""
    done = subprocess.run([sys.executable, "-m", "collie.cli", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout == f"collie {version('collie')}\n", done.stdout + done.stderr
