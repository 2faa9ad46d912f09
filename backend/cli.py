"""`collie serve`: run the labeling service with uvicorn on one address.

Tokens for the three built-in principals (operator, trainer, labeler) come from COLLIE_*_TOKEN or
are generated; they are printed, and written to --tokens-json when given. Port 0 picks a free port;
the bound URL is printed either way (and written to the tokens file as "api")."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import socket
import sys
from pathlib import Path

from pydantic import SecretStr

from backend.services.auth import ROLES, new_token
from backend.settings import Settings


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8000, help="port; 0 picks a free one (default 8000)")
    parser.add_argument("--db", type=Path, help="SQLite file (default: COLLIE_DATABASE_URL, else ./collie.db)")
    parser.add_argument(
        "--fd", type=int, default=None, help="serve on this inherited listening socket (instead of --host/--port)"
    )
    parser.add_argument("--tokens-json", type=Path, help="write {api, tokens: {operator, trainer, labeler}} here")
    parser.add_argument("--no-generate-tokens", action="store_true", help="only use tokens from the environment")
    parser.add_argument("--log-level", default="warning")


def settings_from(args: argparse.Namespace) -> tuple[Settings, dict[str, str]]:
    """Settings from the environment, with --db and generated bootstrap tokens filled in."""
    overrides: dict[str, object] = {}
    if args.db is not None:
        overrides["database_url"] = f"sqlite:///{args.db.resolve()}"
    tokens: dict[str, str] = {}
    for role in ROLES:
        given = os.environ.get(f"COLLIE_{role.upper()}_TOKEN")
        if given is None and not args.no_generate_tokens:
            given = new_token()
            overrides[f"{role}_token"] = SecretStr(given)
        if given is not None:
            tokens[role] = given
    return Settings(**overrides), tokens  # type: ignore[arg-type]  # pydantic-settings validates the overrides


def inherited(fd: int) -> tuple[socket.socket, str]:
    """The listening socket a parent bound for us (`collie up` binds it before we start, so the
    others can connect while we import: their requests queue until we serve), and its URL."""
    try:
        sock = socket.socket(fileno=fd)
    except OSError as exc:
        raise SystemExit(f"collie serve: error: --fd {fd} is not an open socket: {exc}") from None
    host, port = sock.getsockname()[:2]
    return sock, f"http://{f'[{host}]' if ':' in host else host}:{port}"


def run(args: argparse.Namespace) -> int:
    from backend.main import create_app
    from backend.server import bind, uvicorn_server
    from collie.startup import mark

    mark("imports")  # FastAPI, SQLAlchemy, the routes

    settings, tokens = settings_from(args)
    generated = {r for r in tokens if f"COLLIE_{r.upper()}_TOKEN" not in os.environ}
    app = create_app(settings)
    mark("app built")  # the database opened and migrated
    sock, url = inherited(args.fd) if args.fd is not None else bind(args.host, args.port)
    if args.tokens_json is not None:  # written whole, then renamed: a watcher never reads half a file
        args.tokens_json.parent.mkdir(parents=True, exist_ok=True)
        partial = args.tokens_json.with_suffix(".partial")
        partial.unlink(missing_ok=True)
        partial.touch(mode=0o600)  # secrets: readable by this user only
        partial.write_text(json.dumps({"api": url, "tokens": tokens}, indent=1))
        partial.replace(args.tokens_json)
    print(f"collie service listening on {url}  (API docs: {url}/docs)", flush=True)
    for role, token in tokens.items():  # secrets given through the environment or a file stay out of logs
        shown = token if role in generated and args.tokens_json is None else None
        where = "(from environment)" if role not in generated else f"(in {args.tokens_json})"
        print(f"  {role} token: {shown or where}", flush=True)
    # uvicorn shuts down cleanly, then re-raises Ctrl-C: for us that is a normal exit.
    with contextlib.suppress(KeyboardInterrupt):
        uvicorn_server(app, args.log_level).run(sockets=[sock])
    return 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(prog="collie serve", description=__doc__)
    add_arguments(parser)
    sys.exit(run(parser.parse_args()))
