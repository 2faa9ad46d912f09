"""Serving an app on a socket bound up front, so port 0 works and the URL is known before the first
request: `collie serve` runs it in the foreground; tests, benchmarks and `collie up` in a thread."""

from __future__ import annotations

import logging
import re
import socket
import threading
import time
from collections.abc import Callable

import uvicorn
from fastapi import FastAPI

from collie.addresses import link_host


def bind(host: str, port: int) -> tuple[socket.socket, str]:
    """A listening socket and its URL (port 0 → a free port)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(128)  # listening before the banner says so: early clients queue until uvicorn serves
    return sock, url_of(sock)


def url_of(sock: socket.socket) -> str:
    """The URL of a bound socket."""
    bound_host, bound_port = sock.getsockname()[:2]
    return f"http://{link_host(bound_host)}:{bound_port}"


class Server(uvicorn.Server):
    """uvicorn that tells the app a shutdown began (`app.state.begin_shutdown`, when it has one)
    before it waits for the open requests: long polls answer and streams end at once, instead of
    holding the exit until the graceful timeout and being cancelled (a 500 and a traceback each)."""

    def __init__(self, config: uvicorn.Config, app: FastAPI) -> None:
        super().__init__(config)
        self.app = app

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        begin: Callable[[], object] | None = getattr(self.app.state, "begin_shutdown", None)
        if begin is not None:
            begin()
        await super().shutdown(sockets)


class TokensOutOfLog(logging.Filter):
    """Blanks `access_token=…` in uvicorn's own lines: with the access log off it still logs each
    refused WebSocket upgrade at info with its path and query string, and the dashboard's streams
    carry their token there (an EventSource sends no headers)."""

    TOKEN = re.compile(r"(access_token=)[^&\s\"]*")

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(self.TOKEN.sub(r"\1…", a) if isinstance(a, str) else a for a in record.args)
        record.msg = self.TOKEN.sub(r"\1…", str(record.msg))
        return True


def uvicorn_server(app: FastAPI, log_level: str = "warning") -> uvicorn.Server:
    # A short graceful timeout: a request still running after the waits end should not hold the exit.
    config = uvicorn.Config(app, log_level=log_level, access_log=False, timeout_graceful_shutdown=2, lifespan="on")
    uvicorn_log = logging.getLogger("uvicorn.error")
    if not any(isinstance(f, TokensOutOfLog) for f in uvicorn_log.filters):
        uvicorn_log.addFilter(TokensOutOfLog())
    return Server(config, app)


class BackgroundServer:
    """uvicorn in a daemon thread. `with BackgroundServer(app) as server: server.url`. `sock`: serve
    on that listening socket instead of binding one (a `dup()` of one the caller holds keeps the
    port across a restart, as `collie up` keeps the service's: no other process can take it)."""

    def __init__(
        self,
        app: FastAPI,
        host: str = "127.0.0.1",
        port: int = 0,
        sock: socket.socket | None = None,
        log_level: str = "warning",
    ) -> None:
        self.app = app
        self._sock, self.url = bind(host, port) if sock is None else (sock, url_of(sock))
        self.server = uvicorn_server(app, log_level)
        self._thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self._sock]}, daemon=True)

    def start(self, timeout_s: float = 10.0) -> BackgroundServer:
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the service did not start")
            time.sleep(0.01)
        return self

    def stop(self, timeout_s: float = 10.0) -> None:
        self.server.should_exit = True
        self._thread.join(timeout_s)
        self._sock.close()

    def __enter__(self) -> BackgroundServer:
        return self.start()

    def __exit__(self, *_: object) -> None:
        self.stop()
