"""A TCP relay on 127.0.0.1 in front of a real service whose open connections can be stalled: a
request already on its way hangs (as over a dropped Wi-Fi link, or a proxy that holds it), while a
connection opened after the stall goes through. That is how one page's label can still be in flight
when the same tab, reloaded, talks to the service afresh."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager, suppress


class StallingRelay:
    def __init__(self, target: tuple[str, int]) -> None:
        self.target = target
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.listener.settimeout(0.2)
        self._lock = threading.Lock()
        self._open: list[threading.Event] = []  # one per connection: set while its bytes flow
        self._sockets: list[socket.socket] = []
        self._done = threading.Event()
        self._accepting = threading.Thread(target=self._accept, name="stalling-relay", daemon=True)
        self._accepting.start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.listener.getsockname()[1]}"

    def stall(self) -> None:
        """Every connection open now stops passing bytes (both ways) until `resume`; new ones flow."""
        with self._lock:
            for flowing in self._open:
                flowing.clear()

    def resume(self) -> None:
        with self._lock:
            for flowing in self._open:
                flowing.set()

    def close(self) -> None:
        self._done.set()
        self.resume()
        self._accepting.join(5)
        self.listener.close()
        with self._lock:
            for sock in self._sockets:
                with suppress(OSError):
                    sock.close()

    def _accept(self) -> None:
        while not self._done.is_set():
            try:
                client, _ = self.listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            server = socket.create_connection(self.target)
            flowing = threading.Event()
            flowing.set()
            with self._lock:
                self._open.append(flowing)
                self._sockets += [client, server]
            for source, sink in ((client, server), (server, client)):
                threading.Thread(target=self._pump, args=(source, sink, flowing), daemon=True).start()

    def _pump(self, source: socket.socket, sink: socket.socket, flowing: threading.Event) -> None:
        with suppress(OSError):
            while chunk := source.recv(65536):
                flowing.wait()  # held here while stalled: the bytes wait, the connection stays open
                sink.sendall(chunk)
        for sock in (sink, source):  # one side closed: so does the other
            with suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)


@contextmanager
def stalling_relay(url: str) -> Iterator[StallingRelay]:
    """A relay to the service at `url` (http://host:port) for the block's length."""
    host, port = url.removeprefix("http://").rstrip("/").split(":")
    relay = StallingRelay((host, int(port)))
    try:
        yield relay
    finally:
        relay.close()
