"""Request body limits, enforced while a body is read: 413 with a JSON detail. Posting a feedback
session or rollouts gets a large limit (by path suffix); every other request a small one."""

from __future__ import annotations

import json
from typing import Any

from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send


class BodyTooLarge(HTTPException):
    """An HTTPException, so the framework's body reader passes it on as a 413 (not a parse error)."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, _detail(limit))


def declared_length(value: str | bytes | None) -> int | None:
    """A Content-Length header's number; None when absent or not ASCII digits ("²" is a digit to
    str.isdigit, but no int)."""
    if value is None or not (value.isascii() and value.isdigit()):
        return None
    return int(value)


def _detail(limit: int) -> str:
    return f"request body larger than {limit} bytes"


class BodyLimit:
    def __init__(self, app: ASGIApp, default_bytes: int, by_suffix: dict[str, int]) -> None:
        self.app = app
        self.default_bytes = default_bytes
        self.by_suffix = by_suffix

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in ("GET", "HEAD", "OPTIONS", "DELETE"):
            await self.app(scope, receive, send)
            return
        suffix = scope["path"].rsplit("/", 1)[-1]
        limit = self.by_suffix.get(suffix, self.default_bytes)
        raw = dict(scope["headers"]).get(b"content-length")
        declared = declared_length(raw)
        if raw is not None and (declared is None or declared > limit):
            await _reject(send, limit)
            return
        seen = 0
        started = False

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > limit:
                raise BodyTooLarge(limit)
            return message

        async def tracked(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted, tracked)
        except BodyTooLarge:
            if not started:
                await _reject(send, limit)


async def _reject(send: Send, limit: int) -> None:
    body = json.dumps({"detail": _detail(limit)}).encode()
    headers: list[Any] = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
    ]
    await send({"type": "http.response.start", "status": 413, "headers": headers})
    await send({"type": "http.response.body", "body": body})
