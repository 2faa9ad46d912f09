"""Where links point. A socket bound to every interface (0.0.0.0) is reached by this machine's own
parts through the loopback, and by people on other machines at this machine's network address,
which is what a link handed to them must name."""

from __future__ import annotations

import ipaddress
import socket

EVERY_INTERFACE = ("0.0.0.0", "")


def is_loopback(host: str) -> bool:
    """Only this machine can reach `host` (127.0.0.0/8, ::1, localhost)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def local_address(host: str) -> str:
    """How this machine's parts reach a socket bound to `host`."""
    return "127.0.0.1" if host in EVERY_INTERFACE else host


def network_address() -> str | None:
    """This machine's IPv4 address on its network: the one its default route leaves from, else a
    non-loopback one its name resolves to; None without either (no network)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))  # a UDP connect sends nothing: it only picks the interface
            return str(probe.getsockname()[0])
        except OSError:
            pass
    try:
        found = socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)
    except OSError:
        return None
    return next((str(a[4][0]) for a in found if not is_loopback(str(a[4][0]))), None)


def link_host(host: str) -> str:
    """The host a link names for a socket bound to `host` (every interface: the network address,
    else this machine's name)."""
    if host not in EVERY_INTERFACE:
        return f"[{host}]" if ":" in host else host
    return network_address() or socket.gethostname()


def not_listenable(host: str) -> str | None:
    """Why this machine cannot listen on `host` (not one of its addresses: the reason the system
    gives), None if it can. Asked before anything starts: a server told to bind it fails later, or
    (viser) retries it forever, silent."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        try:
            probe.bind((host, 0))
        except OSError as exc:  # socket.gaierror included
            return exc.strerror or str(exc)
    return None
