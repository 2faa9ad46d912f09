"""The error answers of the API as /openapi.json documents them, so a client written from the
schema knows them (their bodies: collie/schemas.py; backend/errors.py shapes them)."""

from __future__ import annotations

from typing import Any

from collie.schemas import ErrorBody, NotHeld, OutOfScope

Responses = dict[int | str, dict[str, Any]]

SIGNED_IN: Responses = {  # every route but /health
    401: {"model": ErrorBody, "description": "no token, or an unknown or revoked one"},
    403: {
        "model": OutOfScope | ErrorBody,
        "description": "a role that may not do this (`detail` only), or a run outside the token's scope "
        "(`OutOfScope`: the caller may go on with other runs)",
    },
    404: {"model": ErrorBody, "description": "no such run, query or labeler"},
}
CLAIMING: Responses = {
    409: {
        "model": ErrorBody,
        "description": "the run takes no labels now (finished, failed or stopping), or the labeler's other "
        "tabs hold as many segments as MAX_TABS tabs may",
    },
}
LABELLING: Responses = {
    409: {
        "model": NotHeld | ErrorBody,
        "description": "a tab that does not hold the query's lease (`NotHeld`: why, as `reason`), or another "
        "conflict (`detail` only): the query leased to someone else, labelled already, retired, a "
        "client_request_id reused for another submission, a run that takes no labels",
    },
}
