"""The boundaries hold in an install, not only in the checkout: a wheel built from the tree,
installed into a fresh virtual environment (its dependencies borrowed from this one, the checkout
out of sight), serves the operators' dashboard and replays models without the trainer."""

from __future__ import annotations

import json
import os
import site
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow

CHECK = """
import json, sys, urllib.request
from pathlib import Path
import backend, collie
from backend.main import create_app
from backend.server import BackgroundServer
from backend.settings import Settings
from collie.mjmodels import load_model
from labeling_ui.models import replay_model

settings = Settings(database_url=f"sqlite:///{Path(sys.argv[1]) / 'collie.db'}", operator_token="op-token-0123456789")
with BackgroundServer(create_app(settings)) as server:
    page = urllib.request.urlopen(server.url + "/", timeout=10).read().decode()
    script = urllib.request.urlopen(server.url + "/js/main.js", timeout=10).read().decode()
print(json.dumps({
    "files": [backend.__file__, collie.__file__],
    "page": "<title>" in page and "js/main.js" in page,
    "script": "import" in script,
    "car": load_model("car").nq,
    "point": replay_model("point").nq,
    "trainer": "trainer" in sys.modules or "torch" in sys.modules,
}))
"""


def test_an_installed_wheel_serves_the_dashboard(tmp_path: Path) -> None:
    wheels, venv = tmp_path / "wheels", tmp_path / "venv"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # the checkout stays out of sight
    pip = [sys.executable, "-m", "pip", "-q", "--disable-pip-version-check"]
    subprocess.run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(wheels), str(ROOT)], check=True)
    (wheel,) = wheels.glob("collie-*.whl")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    subprocess.run([*pip, "--python", str(python), "install", "--no-deps", str(wheel)], check=True, env=env)
    # dependencies from this environment as plain paths (their .pth hooks, e.g. an editable install
    # of the checkout, do not run), after the venv's own site-packages where the wheel went
    (purelib,) = (venv / "lib").glob("python3*/site-packages")
    (purelib / "borrowed.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    out = subprocess.run(
        [str(python), "-c", CHECK, str(tmp_path)], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-3000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert all(Path(f).resolve().is_relative_to(venv.resolve()) for f in seen["files"]), seen["files"]
    assert seen["page"] and seen["script"], "the dashboard is not in the wheel"
    assert seen["car"] == 9 and seen["point"] == 2 and not seen["trainer"]
