"""The app: `create_app(settings)` migrates the database, installs the bootstrap tokens and mounts
the routes under /api (and the dashboard at / when web_dir holds one)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from pydantic import BaseModel
from sqlalchemy.exc import DBAPIError

from backend import __version__, errors, migrate
from backend.bodies import SessionParser
from backend.db import Database
from backend.headers import SecurityHeaders
from backend.limits import BodyLimit
from backend.routes import control, health, labelers, labels, queries, runs, stream, telemetry, web
from backend.routes.responses import SIGNED_IN
from backend.services import auth
from backend.services.errors import first_line
from backend.services.events import EventHub
from backend.services.fanout import StreamFeed
from backend.services.trainer_contact import TrainerContact
from backend.settings import Settings
from collie.schemas import (
    SERVED_TEACHER_PRINCIPAL,
    FeedbackPolicy,
    LabelerCreate,
    LabelerScope,
    LabelSubmit,
    MetricsIn,
    QualitySettings,
    RetireRequest,
    RolloutsIn,
    RunCreate,
    RunInstructions,
    SessionPost,
    StatusUpdate,
    UndoRequest,
)

log = logging.getLogger("collie.service")
# Every request body is read by the route itself (deps.parse_body), after its caller is checked.
RAW_BODIES = (
    SessionPost,
    RunCreate,
    StatusUpdate,
    FeedbackPolicy,
    RetireRequest,
    LabelSubmit,
    UndoRequest,
    MetricsIn,
    RolloutsIn,
    LabelerCreate,
    LabelerScope,
    QualitySettings,
    RunInstructions,
)


def _document_raw_bodies(app: FastAPI, models: tuple[type[BaseModel], ...]) -> None:
    """Bodies read with parse_body are not seen by FastAPI: add their schemas to the components."""
    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = build()
            components = schema.setdefault("components", {}).setdefault("schemas", {})
            for model in models:
                body = model.model_json_schema(ref_template="#/components/schemas/{model}")
                for name, definition in body.pop("$defs", {}).items():
                    components.setdefault(name, definition)
                components.setdefault(model.__name__, body)
        assert app.openapi_schema is not None  # build() stored it; the components were added in place
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]  # FastAPI's documented way to extend the schema


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    hub = EventHub()
    db = Database(
        settings.database_url,
        publisher=hub.publish,
        background_checkpoints=True,
        synchronous=settings.sqlite_synchronous,
    )
    older = migrate.bring_up_to_date(db.engine)
    if older is not None:  # a warning: an older collie can no longer open it
        log.warning(migrate.upgraded(settings.database_url, older))
    with db.write() as conn:
        for role in auth.ROLES:
            token = getattr(settings, f"{role}_token")
            if token is not None and not auth.bootstrap(conn, role, token.get_secret_value()):
                log.warning("the built-in %s principal is revoked: its token stays refused", role)
        teacher = settings.teacher_token
        if teacher is not None and not auth.bootstrap(
            conn, "labeler", teacher.get_secret_value(), SERVED_TEACHER_PRINCIPAL
        ):
            log.warning("the %s principal is revoked: COLLIE_TEACHER_TOKEN stays refused", SERVED_TEACHER_PRINCIPAL)

    async def checkpoints() -> None:
        # A checkpoint writes the database file: while it cannot be written (full disk, read-only
        # files) each one fails; keep trying, or the log would grow unchecked once it can again.
        failing = False
        while True:
            await asyncio.sleep(1.0)
            try:
                await asyncio.to_thread(db.checkpoint)
            except DBAPIError as exc:
                if not failing:
                    log.warning("checkpoint failed, retrying every second: %s", first_line(exc.orig))
                failing = True
                continue
            if failing:
                log.warning("checkpoint: the database is written again")
                failing = False

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        hub.bind(asyncio.get_running_loop())
        app.state.feed = StreamFeed(db, hub, settings.stream_poll_s)
        app.state.feed.start()
        checkpointer = asyncio.create_task(checkpoints())
        yield
        checkpointer.cancel()
        app.state.feed.stop()
        app.state.session_parser.stop()
        try:  # the last one: on a full disk the log stays, and the next start reads it (nothing lost)
            db.checkpoint()
        except DBAPIError as exc:
            log.warning("the last checkpoint failed; the write-ahead log keeps every write: %s", first_line(exc.orig))
        db.dispose()

    app = FastAPI(
        title="collie labeling service",
        version=__version__,
        description="Queries, labels, the live label stream and run control for COLLIE runs.",
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.db = db
    app.state.hub = hub
    app.state.session_parser = SessionParser()

    def begin_shutdown() -> None:
        """The server stops (backend/server.py calls this first): long polls answer, streams end."""
        hub.close()
        app.state.feed.close()

    app.state.begin_shutdown = begin_shutdown
    app.state.tokens = auth.TokenCache(settings.token_cache_s)
    app.state.trainer_contact = TrainerContact()
    app.include_router(health.router, prefix="/api")
    for module in (runs, control, queries, labels, telemetry, stream, labelers):
        app.include_router(module.router, prefix="/api", responses=SIGNED_IN)

    errors.install(app)

    large = {"sessions": settings.max_session_bytes, "rollouts": settings.max_rollouts_bytes}
    _document_raw_bodies(app, RAW_BODIES)
    app.add_middleware(BodyLimit, default_bytes=settings.max_body_bytes, by_suffix=large)
    app.add_middleware(SecurityHeaders)  # outermost: also on the 413s BodyLimit answers itself
    web.install(app, settings.web_dir)  # the operators' dashboard: /api/dashboard, and web/ at /
    return app
