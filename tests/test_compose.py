"""docker-compose.yml, read without docker: which container gets which token, and the teacher's
start check of its own (the service's side: tests/service/test_teacher_principal.py)."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path
from typing import Any

import yaml

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
