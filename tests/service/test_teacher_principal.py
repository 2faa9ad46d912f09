"""`collie up --teacher oracle`'s own labeler for the teacher (collie/teacher_principal.py): made
once, kept in OUT across restarts, made anew where the service no longer takes the kept one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from backend.server import BackgroundServer
from collie.client import CollieClient, NotInScope
from collie.teacher_principal import TOKEN_FILE, teacher_token

from .conftest import TOKENS, make_run_spec, make_session
from .test_cli import collie, start_serve, stop


def test_the_teacher_gets_its_own_labeler_kept_across_restarts_and_renewed_once_refused(
    live: BackgroundServer, operator: CollieClient, trainer: CollieClient, tmp_path: Path
) -> None:
    run = trainer.create_run(make_run_spec())
    first = teacher_token(live.url, TOKENS["operator"], tmp_path, run.id)
    kept = tmp_path / TOKEN_FILE
    assert json.loads(kept.read_text())["name"] == "oracle-teacher" and kept.stat().st_mode & 0o077 == 0
    assert first not in TOKENS.values()
    assert teacher_token(live.url, TOKENS["operator"], tmp_path, run.id) == first  # a restart: the same labeler
    [made] = [p for p in operator.labelers() if p.name == "oracle-teacher"]
    assert made.runs == [run.id]  # the token a stack leaves on a lab database labels no other run
    other = trainer.create_run(make_run_spec())
    trainer.post_session(other.id, make_session(0, 1))
    with CollieClient(live.url, first) as teacher, pytest.raises(NotInScope):
        teacher.claim(other.id)

    operator.revoke(made.id)  # e.g. from the dashboard's labelers list
    renewed = teacher_token(live.url, TOKENS["operator"], tmp_path, run.id)
    assert renewed != first and json.loads(kept.read_text())["name"] == "oracle-teacher-2"
    with CollieClient(live.url, renewed) as teacher:
        assert teacher.claim(run.id) is None  # taken: a labeler of the run (nothing posted yet)

    kept.write_text("{not json")  # a damaged file: a new labeler, not a traceback
    assert teacher_token(live.url, TOKENS["operator"], tmp_path, run.id) not in (first, renewed)

    [newest] = [p for p in operator.labelers() if p.name == json.loads(kept.read_text())["name"]]
    elsewhere = trainer.create_run(make_run_spec()).id
    operator.set_labeler_runs(newest.id, [elsewhere])  # limited to another run (the stack's earlier one, say)
    limited = json.loads(kept.read_text())["token"]
    made_anew = teacher_token(live.url, TOKENS["operator"], tmp_path, run.id)  # one for this run, this run alone
    assert made_anew != limited and [p.runs for p in operator.labelers() if p.name == newest.name] == [[elsewhere]]
    [latest] = [p for p in operator.labelers() if p.name == json.loads(kept.read_text())["name"]]
    assert latest.runs == [run.id]

    with pytest.raises(RuntimeError, match="the oracle teacher's labeler could not be made"):
        teacher_token(live.url, "not-a-token", tmp_path / "elsewhere", run.id)


TEACHER_TOKEN = "teacher-own-token-0123456789"


def compose_env(**tokens: str) -> dict[str, str]:
    """The service's environment under docker-compose.yml: the bootstrap tokens, no other COLLIE_ variable."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("COLLIE_")}
    return {**env, **{f"COLLIE_{role.upper()}_TOKEN": token for role, token in TOKENS.items()}, **tokens}


def test_compose_teachers_token_is_a_labeler_of_its_own(tmp_path: Path) -> None:
    """docker-compose.yml hands COLLIE_TEACHER_TOKEN to the service and (as COLLIE_TOKEN) to the
    teacher: `collie serve` installs it as the labeler `teacher`, so under redundancy 2 the
    teacher labels the queries a person labelled with COLLIE_LABELER_TOKEN, as a second labeler.
    Was: compose gave the teacher COLLIE_LABELER_TOKEN, and the two were one labeler."""
    server, lines = start_serve(tmp_path / "compose.db", None, compose_env(COLLIE_TEACHER_TOKEN=TEACHER_TOKEN))
    try:
        api = lines[0].split()[4]
        with CollieClient(api, TEACHER_TOKEN) as teacher:
            me = teacher.me()
        assert (me.name, me.role) == ("teacher", "labeler")
        with CollieClient(api, TOKENS["trainer"]) as trainer, CollieClient(api, TOKENS["labeler"]) as person:
            run = trainer.create_run(make_run_spec(task="north").model_copy(update={"redundancy": 2}))
            trainer.post_session(run.id, make_session(0, 2))
            for _ in range(2):
                claim = person.claim(run.id)
                assert claim is not None
                person.submit(run.id, claim.query.query_id, 0)
            command = [sys.executable, "-m", "collie.cli", "teacher", "--api", api, "--run", str(run.id)]
            env = {k: v for k, v in os.environ.items() if not k.startswith("COLLIE_")}
            out = subprocess.run(command, env={**env, "COLLIE_TOKEN": TEACHER_TOKEN}, capture_output=True, text=True)
            assert out.returncode == 0 and "labelled 2 queries" in out.stdout, out.stderr  # one labeler: 0
            assert sorted(e.labeler for e in trainer.label_events(run.id)) == ["labeler"] * 2 + ["teacher"] * 2
    finally:
        stop(server)
    banner = server.stdout.read()  # type: ignore[union-attr]  # the lines after the roles'
    assert banner.startswith("  teacher token: (from environment, COLLIE_TEACHER_TOKEN)\n"), banner


def test_a_compose_teacher_token_that_is_unset_weak_or_another_principals_is_said(tmp_path: Path) -> None:
    """Empty (compose passes an unset COLLIE_TEACHER_TOKEN so): no teacher principal. A placeholder, or
    the people's labeler token again: `collie serve` refuses in one line naming it."""
    server, lines = start_serve(tmp_path / "none.db", None, compose_env(COLLIE_TEACHER_TOKEN=""))
    try:
        with CollieClient(lines[0].split()[4], TOKENS["operator"]) as operator:
            assert "teacher" not in {p.name for p in operator.labelers()}
    finally:
        stop(server)
    assert "teacher" not in server.stdout.read()  # type: ignore[union-attr]
    for token, said in [
        ("change-me-teacher", "COLLIE_TEACHER_TOKEN is a placeholder (it holds 'change-me'); use a long random one"),
        (TOKENS["labeler"], "the teacher bootstrap token is already the token of 'labeler'"),
    ]:
        db = tmp_path / f"refused-{len(token)}.db"
        out = collie("serve", "--port", "0", "--db", str(db), env=compose_env(COLLIE_TEACHER_TOKEN=token))
        assert out.returncode != 0 and "Traceback" not in out.stderr, out.stderr
        assert out.stderr.startswith(f"collie serve: error: {said}") and len(out.stderr.splitlines()) == 1
