"""The operators' dashboard: its read API under /api/dashboard and the static page (web/, plain ES
modules and a vendored Plotly, no build step) at /. Open it as {api}/?token=OPERATOR_TOKEN."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles
from starlette.routing import Match, Mount
from starlette.types import Scope

from backend.routes import dashboard, quality
from backend.routes.responses import SIGNED_IN

# backend/web: in the checkout a link to web/, in a wheel the files themselves (package data)
WEB_DIR = (Path(__file__).resolve().parents[1] / "web").resolve()


class PageMount(Mount):
    """The page's mount at /, which leaves /api to the routes: a method a route does not take is
    its 405 (HEAD /api/runs), an unknown API path a 404, instead of a missing file of the page."""

    def matches(self, scope: Scope) -> tuple[Match, Scope]:
        path = scope.get("path", "")
        if path == "/api" or path.startswith("/api/"):
            return Match.NONE, {}
        return super().matches(scope)


def install(app: FastAPI, web_dir: Path | None = None) -> None:
    """Add the dashboard API (and the run quality settings it edits), then serve `web_dir`
    (default: the packaged web/) at / — last, since a mount at / answers every path the routes
    before it did not."""
    app.include_router(dashboard.router, prefix="/api", responses=SIGNED_IN)
    app.include_router(quality.router, prefix="/api", responses=SIGNED_IN)  # the quality panel's one write
    directory = web_dir or WEB_DIR
    if (directory / "index.html").is_file():
        app.router.routes.append(PageMount("/", StaticFiles(directory=directory, html=True), name="web"))
