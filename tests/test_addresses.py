"""Links name an address the labeler's machine can reach: the bound address itself, or for every
interface this machine's network address (never a loopback one, which is the labeler's own machine)."""

from __future__ import annotations

import argparse
import socket

import pytest

from collie.addresses import is_loopback, link_host, local_address, network_address
from collie.argtypes import ipv4_host


def test_loopback_addresses_are_this_machine_only() -> None:
    assert all(is_loopback(h) for h in ("127.0.0.1", "127.0.0.2", "::1", "localhost"))
    assert not any(is_loopback(h) for h in ("0.0.0.0", "10.1.2.3", "192.0.2.2", "example.org"))


def test_a_bound_address_is_named_as_it_is_and_every_interface_by_the_network_address() -> None:
    assert link_host("10.1.2.3") == local_address("10.1.2.3") == "10.1.2.3"
    assert link_host("::1") == "[::1]"
    assert local_address("0.0.0.0") == "127.0.0.1"  # the stack's own parts go through the loopback
    found = network_address()
    assert found is None or not is_loopback(found)
    assert link_host("0.0.0.0") == (found or socket.gethostname())


def test_a_host_to_listen_on_is_an_ipv4_address_or_localhost() -> None:
    assert ipv4_host("0.0.0.0") == "0.0.0.0" and ipv4_host("localhost") == "127.0.0.1"
    for name in ("example.org", "::1", "999.9.9.9"):
        with pytest.raises(argparse.ArgumentTypeError, match="is not an IPv4 address"):
            ipv4_host(name)
