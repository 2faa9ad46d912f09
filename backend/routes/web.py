"""The operators' dashboard: its read API under /api/dashboard and the static page (web/, plain ES
modules and a vendored Plotly, no build step) at /. Open it as {api}/?token=OPERATOR_TOKEN."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from backend.routes import dashboard, quality

# backend/web: in the checkout a link to web/, in a wheel the files themselves (package data)
WEB_DIR = (Path(__file__).resolve().parents[1] / "web").resolve()


def install(app: FastAPI, web_dir: Path | None = None) -> None:
    """Add the dashboard API (and the run quality settings it edits), then serve `web_dir`
    (default: the packaged web/) at / — last, since a mount at / answers every path the routes
    before it did not."""
    app.include_router(dashboard.router, prefix="/api")
    app.include_router(quality.router, prefix="/api")  # the quality panel's one write
    directory = web_dir or WEB_DIR
    if (directory / "index.html").is_file():
        app.mount("/", StaticFiles(directory=directory, html=True), name="web")
