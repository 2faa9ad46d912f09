"""The oracle teacher's own principal in a `collie up` stack: a labeler token apart from the one
in the stack's label link. Sharing one, a person labelling through the link and the teacher took
each other's segments (a claim without a tab hands back every query its principal holds, the one
on the person's screen included) and counted as one labeler under redundancy. The token is kept
in OUT/teacher_token.json, so a resumed stack's teacher is the same labeler."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

from collie.client import Backoff, CollieClient, retrying
from collie.tokens import write_secret

NAME = "oracle-teacher"
TOKEN_FILE = "teacher_token.json"


def teacher_token(api: str, operator_token: str, out: Path) -> str:
    """The teacher's labeler token: the one `out` keeps, else a new principal's (created with the
    operator's token, named `oracle-teacher`, or `oracle-teacher-2`… where the name is taken)."""
    path = out / TOKEN_FILE
    try:
        return str(json.loads(path.read_text())["token"])
    except (OSError, ValueError, KeyError, TypeError):  # none yet, or damaged: a new principal
        pass
    with CollieClient(api, operator_token) as client:
        taken = {p.name for p in retrying(client.labelers, Backoff(max_s=2.0), attempts=30)}
        names = itertools.chain([NAME], (f"{NAME}-{i}" for i in itertools.count(2)))
        created = client.create_labeler(next(n for n in names if n not in taken))  # once: a retry might make two
    write_secret(path, json.dumps({"name": created.name, "token": created.token}))
    return created.token
