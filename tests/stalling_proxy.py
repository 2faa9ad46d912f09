"""A TCP relay on 127.0.0.1 in front of a real service whose open connections can be stalled: a
request already on its way hangs (as over a dropped Wi-Fi link, or a proxy that holds it), while a
connection opened after the stall goes through. That is how one page's label can still be in flight
when the same tab, reloaded, talks to the service afresh. It can also lose the answer to one
request the service did receive, as a dropped link or a dying client does."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager, suppress


class StallingRelay:
    def __init__(self, target: tuple[str, int], lose_answer_to: bytes | None = None) -> None:
        """`lose_answer_to`: the first request that starts so (b"POST /runs") reaches the service,
        but its answer is held back for good (`drop_held` then closes its connection unanswered)."""
        self.target = target
        self.lose_answer_to = lose_answer_to
        self._held: list[tuple[socket.socket, threading.Event]] = []  # a client side whose answer is held, its gate
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

    def _loses(self, request: bytes, client: socket.socket, answering: threading.Event) -> bool:
        with self._lock:
            if self.lose_answer_to is None or self._held or not request.startswith(self.lose_answer_to):
                return False
            self._held.append((client, answering))
            return True

    @property
    def holding(self) -> bool:
        with self._lock:
            return bool(self._held)

    def drop_held(self) -> None:
        """Close the connection whose answer is held, as a network drop or a restarting service does."""
        with self._lock:
            for sock, answering in self._held:
                with suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
                answering.set()  # its pump meets the closed socket and ends

    def close(self) -> None:
        self._done.set()
        self.drop_held()
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
            flowing, answering = threading.Event(), threading.Event()
            flowing.set()
            answering.set()
            with self._lock:
                self._open.append(flowing)
                self._sockets += [client, server]
            threading.Thread(target=self._pump, args=(client, server, (flowing,), answering), daemon=True).start()
            threading.Thread(target=self._pump, args=(server, client, (flowing, answering)), daemon=True).start()

    def _pump(
        self,
        source: socket.socket,
        sink: socket.socket,
        gates: tuple[threading.Event, ...],
        answering: threading.Event | None = None,
    ) -> None:
        """Pass source's bytes to sink while `gates` are open; a request's side closes `answering`
        (its answers' gate) when the request is the one whose answer is lost."""
        with suppress(OSError):
            while chunk := source.recv(65536):
                if answering is not None and self._loses(chunk, source, answering):
                    answering.clear()
                for gate in gates:
                    gate.wait()  # held here while stalled: the bytes wait, the connection stays open
                sink.sendall(chunk)
        for sock in (sink, source):  # one side closed: so does the other
            with suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)


@contextmanager
def stalling_relay(url: str, lose_answer_to: bytes | None = None) -> Iterator[StallingRelay]:
    """A relay to the service at `url` (http://host:port) for the block's length."""
    host, port = url.removeprefix("http://").rstrip("/").split(":")
    relay = StallingRelay((host, int(port)), lose_answer_to)
    try:
        yield relay
    finally:
        relay.close()
