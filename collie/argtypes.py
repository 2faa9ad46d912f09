"""argparse types shared by the commands: a bad value is refused by argparse, naming the flag."""

from __future__ import annotations

import argparse
import ipaddress
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit


def port(value: str) -> int:
    """A TCP port, 0 (any free one) to 65535."""
    try:
        number = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a port number") from None
    if not 0 <= number <= 65535:
        raise argparse.ArgumentTypeError(f"{number} is not a port: 0 (any free one) to 65535")
    return number


def ipv4_host(value: str) -> str:
    """An IPv4 address to listen on (whether it is this machine's is for the binding to say);
    `localhost` is 127.0.0.1, what a person typing it means."""
    if value == "localhost":
        return "127.0.0.1"
    try:
        ipaddress.IPv4Address(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{value!r} is not an IPv4 address: 127.0.0.1 (this machine only) or 0.0.0.0 (every interface)"
        ) from None
    return value


def http_url(value: str) -> str:
    """An http:// or https:// URL with a host (the service's address)."""
    parts = urlsplit(value)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise argparse.ArgumentTypeError(f"{value!r} is not an http:// or https:// URL, e.g. http://127.0.0.1:8000")
    try:
        parts.port  # noqa: B018 - raises for a port out of range
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{value!r}: {exc}") from None
    return value


def record_id(value: str) -> int:
    """A run's (or other record's) id: 1 to 2^31 − 1, as the API bounds them (PostgreSQL's INTEGER)."""
    from collie.schemas import MAX_INT  # here: the other types need no pydantic

    try:
        number = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not an id") from None
    if not 1 <= number <= MAX_INT:
        raise argparse.ArgumentTypeError(f"{number} is not an id: 1 to {MAX_INT}")
    return number


def sqlite_file(value: str) -> Path:
    """A SQLite file's path. A database URL is refused without echoing it (it may hold a password):
    PostgreSQL is reached through COLLIE_DATABASE_URL, for `collie serve` and `collie export` alike."""
    if "://" in value:
        raise argparse.ArgumentTypeError(
            "takes a SQLite file's path, not a URL; for PostgreSQL leave --db out and set "
            "COLLIE_DATABASE_URL=postgresql+psycopg://USER:PASSWORD@HOST:5432/DB"
        )
    if not value.strip():  # Path("") is ".", which would be refused as "a folder"
        raise argparse.ArgumentTypeError("is empty: give a SQLite file's path (or leave --db out)")
    return Path(value)


def float_in(low: float, high: float = math.inf, *, low_open: bool = True) -> Callable[[str], float]:
    """A finite number above `low` (or at it: low_open=False) and at most `high`: a rate, a length
    of time. A value out of range would only fail later, each time it is used."""

    def parse(value: str) -> float:
        try:
            number = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{value!r} is not a number") from None
        above = number > low if low_open else number >= low
        if not (math.isfinite(number) and above and number <= high):  # NaN fails every comparison
            bound = f"{'>' if low_open else '≥'} {low:g}" + (f" and ≤ {high:g}" if math.isfinite(high) else "")
            finite = "" if math.isfinite(number) else "a finite number "  # `inf must be ≥ 0` would be wrong
            raise argparse.ArgumentTypeError(f"{value} must be {finite}{bound}")
        return number

    return parse


def int_in(low: int | None, high: int, why: str = "") -> Callable[[str], int]:
    """A whole number up to `high` (and from `low`, None: a check of its own says what is too low);
    `why`: what sets the bound. Unbounded, a huge one fails far from its flag (an overflow, an
    allocation, the service's validation)."""

    def parse(value: str) -> int:
        try:
            number = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{value!r} is not a whole number") from None
        if number > high:
            raise argparse.ArgumentTypeError(f"{number} is more than {high}{f' ({why})' if why else ''}")
        if low is not None and number < low:
            raise argparse.ArgumentTypeError(f"{number} is less than {low}{f' ({why})' if why else ''}")
        return number

    return parse


# numpy's and torch's generators take seeds of 0 to 2^32 − 1 alike (numpy's legacy one no more)
seed = int_in(0, 2**32 - 1, "a random generator's seed")
# an open file a parent process hands down: 0 or more (a descriptor is a C int)
file_descriptor = int_in(0, 2**31 - 1, "a file descriptor")


class Given(argparse.Action):
    """`store` that also records the flag as given (in `given`, which the parser must default to an
    empty frozenset): a resumed run warns about those it ignores, and only those."""

    def __call__(
        self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option: Any = None
    ) -> None:
        setattr(namespace, self.dest, values)
        namespace.given = frozenset({*namespace.given, self.dest})
