"""How a client process gets its token without it showing in a command line (/proc/*/cmdline is
world-readable): `--token-file PATH` (a file only its owner may read) or the COLLIE_TOKEN environment
variable, before the role's COLLIE_<ROLE>_TOKEN. `--token VALUE` is still accepted for people who
type it (write `--token=-abc` for a token that starts with a dash). A tokens file (`collie up`'s
OUT/tokens.json) also serves as a --token-file: its entry for the client's role is taken."""

from __future__ import annotations

import argparse
import json
import os
import re
import secrets
import sys
from pathlib import Path

from collie.whole_files import not_replaceable

TOKEN_ENV = "COLLIE_TOKEN"
HEADER_SAFE = re.compile(r"[!-~]+")  # printable ASCII without spaces: what a bearer header carries
MIN_TOKEN = 16  # a generated token has 43 characters


def random_token() -> str:
    """A new secret token (256 random bits, URL-safe), never starting with '-': pasted after
    `--token`, argparse would take it for an option (1 in 64 of token_urlsafe's would)."""
    while True:
        token = secrets.token_urlsafe(32)
        if not token.startswith("-"):
            return token


def add_token_arguments(parser: argparse.ArgumentParser, role: str) -> None:
    parser.add_argument(
        "--token", default=None, help=f"{role} token (visible to other users in the process list: prefer --token-file)"
    )
    parser.add_argument("--token-file", type=Path, default=None, help=f"file holding the {role} token (mode 0600)")


def resolve_token(args: argparse.Namespace, role: str, from_env: bool = True) -> str | None:
    """The token from --token, --token-file, COLLIE_TOKEN or COLLIE_<ROLE>_TOKEN, first found
    (from_env=False: only what was asked for on the command line). A token goes into an HTTP
    header, so one that cannot is refused here, naming where it came from but never its text."""
    if getattr(args, "token", None):
        return checked(args.token, "--token")
    path: Path | None = getattr(args, "token_file", None)
    if path is not None:
        return _from_file(path, role)
    if not from_env:
        return None
    for name in (TOKEN_ENV, f"COLLIE_{role.upper()}_TOKEN"):
        if os.environ.get(name):
            return checked(os.environ[name], name)
    return None


def checked(token: str, source: str) -> str:
    if not HEADER_SAFE.fullmatch(token):
        raise ValueError(f"{source} does not hold a token (one line of printable characters, no spaces)")
    return token


def _from_file(path: Path, role: str) -> str:
    """A file holding one token, or a tokens file (`collie up`'s OUT/tokens.json): its `role` token."""
    try:
        text = path.read_text().strip()
        mode = path.stat().st_mode
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--token-file {path}: {getattr(exc, 'strerror', None) or 'not text'}") from None
    if not text:
        raise ValueError(f"--token-file {path} is empty")
    if mode & 0o077:
        print(f"collie: warning: --token-file {path} is readable by other users (chmod 600 it)", file=sys.stderr)
    if not text.startswith("{"):
        return checked(text, f"--token-file {path}")
    tokens = read_tokens_file(path)
    if role not in tokens:
        raise ValueError(f"--token-file {path} is a tokens file without a {role} token (it has: {', '.join(tokens)})")
    return checked(tokens[role], f"--token-file {path} ({role})")


def weakness(token: str) -> str | None:
    """Why a token someone chose is guessable (None: it is not): a forgotten placeholder, or short."""
    if not HEADER_SAFE.fullmatch(token):  # clients could never send it
        return "holds spaces or characters a bearer token cannot carry (printable ASCII only)"
    if "change-me" in token.lower():
        return "is a placeholder (it holds 'change-me')"
    if len(token) < MIN_TOKEN:
        return f"is shorter than {MIN_TOKEN} characters"
    return None


def write_secret(path: Path, text: str) -> None:
    """Write a file holding secrets, readable by its owner only, in one rename (a reader never
    sees half of it, and it is never world-readable, not even for a moment). A path that is no
    regular file (/dev/null, a FIFO) or in /dev is written in place, as collie.whole_files does."""
    if not_replaceable(path):
        path.write_text(text)
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    partial.unlink(missing_ok=True)
    fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        partial.replace(path)
    finally:  # a full disk, an immutable file: no copy of the secrets is left beside it
        partial.unlink(missing_ok=True)


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
