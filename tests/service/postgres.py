"""A real PostgreSQL server for the tests, from Debian's `postgresql` binaries (apt-get install
postgresql; the Makefile does): initdb in a temporary directory, `postgres` on a free 127.0.0.1
port, one fresh database per test module. PostgreSQL refuses to run as root, so as root the
server runs as the `postgres` user the package creates (runuser)."""

from __future__ import annotations

import contextlib
import itertools
import os
import pwd
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import psycopg

BIN = Path("/usr/lib/postgresql/15/bin")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class PostgresServer:
    def __init__(self) -> None:
        if not (BIN / "postgres").exists():
            raise RuntimeError(f"{BIN}/postgres missing: `make test` installs it (or: apt-get install -y postgresql)")
        self.root = Path(tempfile.mkdtemp(prefix="collie-pg-"))
        self.as_user: list[str] = []
        if os.geteuid() == 0:
            owner = pwd.getpwnam("postgres")
            os.chown(self.root, owner.pw_uid, owner.pw_gid)
            self.as_user = ["runuser", "-u", "postgres", "--"]
        self.data = self.root / "data"
        self.port = _free_port()
        self._names = itertools.count()
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, timeout_s: float = 60.0) -> PostgresServer:
        """Create the cluster on first use, then run the server (again, after halt())."""
        if not self.data.exists():
            initdb = [str(BIN / "initdb"), "-D", str(self.data), "-U", "postgres", "-A", "trust", "-E", "UTF8"]
            subprocess.run([*self.as_user, *initdb, "--no-sync"], check=True, capture_output=True)
        # fsync off: a test server need not survive a power cut (the service's durability is
        # tested on SQLite); listen on 127.0.0.1 only, the socket directory is our own
        options = ["-p", str(self.port), "-h", "127.0.0.1", "-k", str(self.root), "-F", "-c", "max_connections=200"]
        log = open(self.root / "postgres.log", "ab")  # noqa: SIM115 (the server writes it until stop)
        self.proc = subprocess.Popen(
            [*self.as_user, str(BIN / "postgres"), "-D", str(self.data), *options], stdout=log, stderr=log
        )
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                with psycopg.connect(self.dsn("postgres"), connect_timeout=2):
                    return self
            except psycopg.OperationalError:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(
                        "PostgreSQL did not start: " + (self.root / "postgres.log").read_text()[-2000:]
                    ) from None
                time.sleep(0.1)

    def dsn(self, database: str) -> str:
        return f"postgresql://postgres@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """A fresh, empty database; its SQLAlchemy URL (psycopg 3 driver)."""
        name = f"collie_{next(self._names)}"
        with psycopg.connect(self.dsn("postgres"), autocommit=True) as conn:
            conn.execute(f"CREATE DATABASE {name}")
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{name}"

    def halt(self) -> None:
        """Stop the server as `pg_ctl stop -m fast` does (open connections are cut); the cluster
        stays, and start() runs it again on the same port: an outage."""
        # signal the postmaster itself: a `runuser` in between need not pass the signal on
        with contextlib.suppress(OSError, ValueError):
            pid = int((self.data / "postmaster.pid").read_text().split()[0])
            os.kill(pid, signal.SIGINT)  # fast shutdown
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                os.kill(pid, 0)  # raises once it is gone
                time.sleep(0.1)
            os.kill(pid, signal.SIGKILL)
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()

    def stop(self) -> None:
        self.halt()
        shutil.rmtree(self.root, ignore_errors=True)
