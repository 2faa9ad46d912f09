"""`collie up --teacher oracle`'s own labeler for the teacher (collie/teacher_principal.py): made
once, kept in OUT across restarts, made anew where the service no longer takes the kept one."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.teacher_principal import TOKEN_FILE, teacher_token

from .conftest import TOKENS, make_run_spec


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
    operator.revoke(made.id)  # e.g. from the dashboard's labelers list
    renewed = teacher_token(live.url, TOKENS["operator"], tmp_path, run.id)
    assert renewed != first and json.loads(kept.read_text())["name"] == "oracle-teacher-2"
    with CollieClient(live.url, renewed) as teacher:
        assert teacher.claim(run.id) is None  # taken: a labeler of the run (nothing posted yet)

    kept.write_text("{not json")  # a damaged file: a new labeler, not a traceback
    assert teacher_token(live.url, TOKENS["operator"], tmp_path, run.id) not in (first, renewed)

    [newest] = [p for p in operator.labelers() if p.name == json.loads(kept.read_text())["name"]]
    operator.set_labeler_runs(newest.id, [trainer.create_run(make_run_spec()).id])  # an operator limits it
    with pytest.raises(RuntimeError, match=f"limited to other runs than run {run.id}"):
        teacher_token(live.url, TOKENS["operator"], tmp_path, run.id)  # said, not undone by a new labeler

    with pytest.raises(RuntimeError, match="the oracle teacher's labeler could not be made"):
        teacher_token(live.url, "not-a-token", tmp_path / "elsewhere", run.id)
