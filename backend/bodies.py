"""Large session bodies are validated in a worker process. pydantic holds the GIL for the whole
of a parse (seconds for 100 MiB of floats), so a thread would still stall every other request;
a process does not. The body is spooled to a file as it arrives (the service never holds it in
memory), the worker validates it and writes what post_session stores — each segment's frames
as JSON, its small fields and a shape-only shell to check against the run — to a second file,
which the service unpickles as a stream (no second copy of the bytes)."""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
import os
import pickle
import tempfile
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio
from fastapi import Request
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from backend.services.errors import Unavailable
from collie.processes import end_with_parent
from collie.schemas import EnvDims, QueryFrames, SessionPost

FRAME_FIELDS = frozenset(QueryFrames.model_fields)


@dataclass
class PreparedQuery:
    """Stands in for a validated QueryIn in queries.post_session: the same fields it reads."""

    query_id: str
    start: int
    score: float
    extra: dict[str, Any]
    frames_json: str
    shell: QueryFrames  # the same shapes, rows shared: for shape_errors

    def shape_errors(self, dims: EnvDims) -> list[str]:
        return self.shell.shape_errors(dims)

    def model_dump_json(self, include: frozenset[str] | None = None) -> str:
        assert include is None or set(include) == FRAME_FIELDS, include
        return self.frames_json


def _shell(frames: QueryFrames) -> QueryFrames:
    """Only the shapes: each matrix as its row count of references to its first row."""

    def same(rows: list[list[float]]) -> list[list[float]]:
        return [rows[0]] * len(rows) if rows else []

    return QueryFrames.model_construct(
        skill=frames.skill,
        obs=same(frames.obs),
        obs_packed=frames.obs_packed,
        xy=same(frames.xy),
        pitch=frames.pitch,
        qpos=same(frames.qpos),
        qvel=same(frames.qvel),
        path_xy=None,
    )


def prepare_session(body_path: str) -> tuple[str, Any]:
    """In the worker: ("ok", path of the pickled SessionPost of PreparedQuery) or ("invalid", errors)."""
    from backend.errors import plain_error

    raw = Path(body_path).read_bytes()
    try:
        session = SessionPost.model_validate_json(raw)
    except ValidationError as exc:
        return "invalid", [plain_error({**e, "loc": ("body", *e["loc"])}) for e in exc.errors(include_url=False)[:20]]
    del raw
    queries = [
        PreparedQuery(q.query_id, q.start, q.score, q.extra, q.model_dump_json(include=set(FRAME_FIELDS)), _shell(q))
        for q in session.queries
    ]
    fields = {name: getattr(session, name) for name in type(session).model_fields if name != "queries"}
    # PreparedQuery stands in, duck-typed, for the QueryIn fields post_session reads
    prepared = SessionPost.model_construct(**fields, queries=queries)  # type: ignore[arg-type]  # see above
    fd, out = tempfile.mkstemp(prefix="collie-session-", suffix=".pickle", dir=Path(body_path).parent)
    with os.fdopen(fd, "wb") as file:
        pickle.dump(prepared, file, protocol=5)
    return "ok", out


class SessionParser:
    """One worker process (spawned: the service's threads make fork unsafe), started with the
    first big session (a service that never gets one never starts it) and kept. A worker that
    died (killed, or out of memory on a body) is replaced by the next session that needs it."""

    def __init__(self, spool_dir: Path | None = None) -> None:
        self.spool_dir = spool_dir
        self._pool: ProcessPoolExecutor | None = None

    def stop(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)

    def _worker(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(  # a worker that outlived a killed service would hold its memory
                max_workers=1, mp_context=multiprocessing.get_context("spawn"), initializer=end_with_parent
            )
        return self._pool

    async def _prepare(self, body_path: str) -> tuple[str, Any]:
        """prepare_session in the worker; a body is tried on a fresh worker once more if the worker
        died under it, and refused (503) if it dies again."""
        loop = asyncio.get_running_loop()
        for _ in range(2):
            pool = self._worker()
            try:
                return await loop.run_in_executor(pool, prepare_session, body_path)
            except BrokenProcessPool:
                if self._pool is pool:  # not already replaced by a concurrent request
                    pool.shutdown(wait=False, cancel_futures=True)
                    self._pool = None
        raise Unavailable(
            "the worker validating large sessions died twice on this body (out of memory?); "
            "post the session again, or in smaller sessions"
        )

    async def parse(self, request: Request) -> SessionPost:
        fd, body_path = tempfile.mkstemp(prefix="collie-body-", suffix=".json", dir=self.spool_dir)
        out: str | None = None
        try:
            with os.fdopen(fd, "wb") as file:
                async for chunk in request.stream():
                    file.write(chunk)
            kind, result = await self._prepare(body_path)
            if kind == "invalid":
                raise RequestValidationError(result)
            out = result
            return await anyio.to_thread.run_sync(_load, out)
        finally:
            for path in (body_path, out):
                if path is not None:
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(path)


def _load(path: str) -> SessionPost:
    with open(path, "rb") as file:
        return pickle.load(file)  # our own worker's file, never a client's bytes
