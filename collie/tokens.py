"""How a client process gets its token without it showing in a command line (/proc/*/cmdline is
world-readable): `--token-file PATH` (a file only its owner may read) or the COLLIE_TOKEN environment
variable, before the role's COLLIE_<ROLE>_TOKEN. `--token VALUE` is still accepted for people who
type it (write `--token=-abc` for a token that starts with a dash)."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

TOKEN_ENV = "COLLIE_TOKEN"


def add_token_arguments(parser: argparse.ArgumentParser, role: str) -> None:
    parser.add_argument(
        "--token", default=None, help=f"{role} token (visible to other users in the process list: prefer --token-file)"
    )
    parser.add_argument("--token-file", type=Path, default=None, help=f"file holding the {role} token (mode 0600)")


def resolve_token(args: argparse.Namespace, role: str, from_env: bool = True) -> str | None:
    """The token from --token, --token-file, COLLIE_TOKEN or COLLIE_<ROLE>_TOKEN, first found
    (from_env=False: only what was asked for on the command line)."""
    if getattr(args, "token", None):
        return args.token
    path: Path | None = getattr(args, "token_file", None)
    if path is not None:
        try:
            token = path.read_text().strip()
        except OSError as exc:
            raise ValueError(f"--token-file {path}: {exc.strerror}") from None
        if not token:
            raise ValueError(f"--token-file {path} is empty")
        return token
    if not from_env:
        return None
    return os.environ.get(TOKEN_ENV) or os.environ.get(f"COLLIE_{role.upper()}_TOKEN") or None


def write_secret(path: Path, text: str) -> None:
    """Write a file holding secrets, readable by its owner only, in one rename (a reader never
    sees half of it, and it is never world-readable, not even for a moment)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    partial.unlink(missing_ok=True)
    fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    partial.replace(path)


def read_tokens_file(path: Path) -> dict[str, str]:
    """The role → token map of a tokens file (`collie serve --tokens-json`, `collie up`'s
    OUT/tokens.json); ValueError naming the file if it is not one."""
    try:
        tokens = json.loads(path.read_text())["tokens"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path} is not a tokens file ({type(exc).__name__}: {exc})") from None
    if not isinstance(tokens, dict):
        raise ValueError(f"{path} is not a tokens file (its tokens are not a map of role to token)")
    return {str(role): str(token) for role, token in tokens.items() if token}
