"""The oracle teacher's own principal in a `collie up` stack: a labeler token apart from the one
in the stack's label link. Sharing one, a person labelling through the link and the teacher took
each other's segments (a claim without a tab hands back every query its principal holds, the one
on the person's screen included) and counted as one labeler under redundancy. The token is kept
in OUT/teacher_token.json, so a resumed stack's teacher is the same labeler. It is made for the
stack's run alone: the token each stack leaves on a lab database labels no other run."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

from collie.client import ApiError, Backoff, CollieClient, Conflict, Unauthorized, Unavailable, retrying
from collie.schemas import TEACHER_PRINCIPAL, LabelerCreated
from collie.tokens import write_secret

NAME = TEACHER_PRINCIPAL
TOKEN_FILE = "teacher_token.json"
BACKOFF = Backoff(max_s=2.0)
ATTEMPTS = 8  # about 10 s of a service that does not answer (it answered a moment ago), then an error


def teacher_token(api: str, operator_token: str, out: Path, run_id: int) -> str:
    """The teacher's labeler token: the one `out` keeps while the service takes it for run
    `run_id`, else a new principal's limited to that run (made with the operator's token, named
    `oracle-teacher`, or `oracle-teacher-2`… where the name is taken). RuntimeError when the service
    refuses."""
    path = out / TOKEN_FILE
    try:
        with CollieClient(api, operator_token) as client:
            kept = _kept(path)
            if kept is not None and _takes(api, kept, run_id):
                return kept
            created = _create(client, run_id)
    except (ApiError, Unavailable) as exc:
        raise RuntimeError(f"the oracle teacher's labeler could not be made: {exc}") from None
    write_secret(path, json.dumps({"name": created.name, "token": created.token}))
    return created.token


def _kept(path: Path) -> str | None:
    try:
        return str(json.loads(path.read_text())["token"])
    except (OSError, ValueError, KeyError, TypeError):  # none yet, or damaged: a new principal
        return None


def _takes(api: str, token: str, run_id: int) -> bool:
    """Whether the service takes `token` for run `run_id`: not revoked, not from another database,
    not limited to other runs (the stack's earlier run, or an operator's choice: either way a new
    labeler limited to this run is made, which labels nothing else)."""
    with CollieClient(api, token) as teacher:
        try:
            retrying(lambda: teacher.run(run_id), BACKOFF, attempts=ATTEMPTS)
        except Unauthorized:  # NotInScope too (a kind of it)
            return False
    return True


def _create(client: CollieClient, run_id: int) -> LabelerCreated:
    taken = {p.name for p in retrying(client.labelers, BACKOFF, attempts=ATTEMPTS)}
    for i in itertools.count(1):
        name = NAME if i == 1 else f"{NAME}-{i}"
        if name in taken:
            continue
        try:
            return client.create_labeler(name, runs=[run_id])  # once: a retry of an unanswered one might make two
        except Conflict:  # taken meanwhile (another stack on the same lab database)
            continue
    raise AssertionError("never: the count has no end")
