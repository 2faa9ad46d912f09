"""Errors a service raises; main.py turns them into JSON 4xx answers."""

from __future__ import annotations

from collie.schemas import NotHeld, NotHeldReason


class ServiceError(Exception):
    status = 400

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


class NotFound(ServiceError):
    status = 404


class Conflict(ServiceError):
    status = 409


class Invalid(ServiceError):
    status = 422


class Unavailable(ServiceError):
    status = 503


class TabNotHolding(Conflict):
    """A label from a tab that does not hold the query's lease; the answer is a NotHeld body."""

    def __init__(self, query_id: str, reason: NotHeldReason, detail: str) -> None:
        super().__init__(detail)
        self.body = NotHeld(detail=detail, reason=reason, query_id=query_id)
