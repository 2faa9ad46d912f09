"""docker-compose.yml, read without docker: which container gets which token, and the teacher's
start check of its own (the service's side: tests/service/test_teacher_principal.py)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import yaml
from service.conftest import TOKENS, settings_for

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import CollieClient

ROOT = Path(__file__).resolve().parents[1]
TEACHER_TOKEN = "${COLLIE_TEACHER_TOKEN:-}"  # optional: `docker compose up` without the teacher needs none


def services() -> dict[str, Any]:
    return dict(yaml.safe_load((ROOT / "docker-compose.yml").read_text())["services"])


def interpolated(text: str, env: dict[str, str]) -> str:
    """What compose makes of `text`: `$$` is a `$`, `${NAME:-default}` the variable or its default."""

    def value(match: re.Match[str]) -> str:
        if match.group(0) == "$$":
            return "$"
        return env.get(match.group(1)) or match.group(2) or ""

    return re.sub(r"\$\$|\$\{(\w+)(?::-([^}]*))?\}", value, text)


def test_the_teacher_labels_with_a_token_of_its_own_that_the_service_installs() -> None:
    """Was: the teacher got COLLIE_LABELER_TOKEN, the people's, and was one labeler with them."""
    got = services()
    assert got["teacher"]["environment"] == {"COLLIE_TOKEN": TEACHER_TOKEN}
    assert got["service"]["environment"]["COLLIE_TEACHER_TOKEN"] == TEACHER_TOKEN
    people = [name for name, service in got.items() if "COLLIE_LABELER_TOKEN" in (service.get("environment") or {})]
    assert people == ["service"]  # the service installs it; people type it into the labeling UI


def test_the_teacher_without_its_token_says_where_to_put_it() -> None:
    """The teacher's own command, as compose hands it to sh, with COLLIE_TEACHER_TOKEN unset."""
    command = services()["teacher"]["command"]
    assert command[:2] == ["sh", "-c"]
    script = interpolated(command[2], {})
    env = {"PATH": os.environ["PATH"], "COLLIE_TOKEN": ""}
    out = subprocess.run(["sh", "-c", script], env=env, capture_output=True, text=True, timeout=30)
    assert out.returncode != 0 and out.stdout == ""  # stopped before collie starts
    assert "put COLLIE_TEACHER_TOKEN in .env" in out.stderr and "Traceback" not in out.stderr, out.stderr


def test_the_env_example_names_every_token_compose_passes() -> None:
    compose = (ROOT / "docker-compose.yml").read_text()
    example = (ROOT / "docs" / "compose.env.example").read_text()
    tokens = set(re.findall(r"\$\{(COLLIE_\w+_TOKEN)", compose))
    assert tokens == {"COLLIE_OPERATOR_TOKEN", "COLLIE_TRAINER_TOKEN", "COLLIE_LABELER_TOKEN", "COLLIE_TEACHER_TOKEN"}
    assert all(re.search(rf"^(# )?{name}=change-me-", example, re.MULTILINE) for name in tokens)


def trainer_start(out: Path, api: str) -> subprocess.Popen[str]:
    """The trainer's command as compose hands it to sh (the smoke preset), on `out` for /runs/compose
    and `api` for the service's address; this venv's collie and python for the image's."""
    script = interpolated(services()["trainer"]["command"][2], {"COLLIE_PRESET": "smoke"})
    script = script.replace("/runs/compose", str(out)).replace("http://service:8000", api)
    path = f"{Path(sys.executable).parent}:{os.environ['PATH']}"
    env = {**os.environ, "PATH": path, "COLLIE_TRAINER_TOKEN": TOKENS["trainer"], "COLLIE_TASK": ""}
    return subprocess.Popen(
        ["sh", "-c", script],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def test_a_trainer_that_died_before_its_first_checkpoint_goes_on_with_its_run(tmp_path: Path) -> None:
    """Was: --resume only once checkpoint.pt existed, and no --run-id: a trainer killed between making
    its run (service_run.json) and its first checkpoint exited 2 at every later `docker compose up`
    ("holds no checkpoint: give --run-id"); and no restart policy brought it back at all."""
    assert services()["trainer"]["restart"] == "on-failure:5"
    out = tmp_path / "compose"
    with BackgroundServer(create_app(settings_for(tmp_path / "collie.db"))) as server:
        first = trainer_start(out, server.url)
        deadline = time.monotonic() + 180
        while not (out / "service_run.json").exists():
            assert first.poll() is None and time.monotonic() < deadline, first.communicate()[1][-3000:]
            time.sleep(0.05)
        os.killpg(first.pid, signal.SIGKILL)  # docker kill, the OOM killer, a reboot
        first.wait()
        assert not (out / "checkpoint.pt").exists()
        run_id = json.loads((out / "service_run.json").read_text())["run_id"]
        second = trainer_start(out, server.url)
        try:
            with CollieClient(server.url, TOKENS["operator"]) as operator:
                while operator.run(run_id).queue.pending == 0:  # it trained on to its first feedback session
                    assert second.poll() is None and time.monotonic() < deadline, second.communicate()[1][-3000:]
                    time.sleep(0.2)
                assert [r.id for r in operator.runs()] == [run_id]  # the same run, not a new one beside it
        finally:
            os.killpg(second.pid, signal.SIGKILL)
            second.wait()
