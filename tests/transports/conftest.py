"""Fixtures for the transport tests: connected pairs of every backend configuration."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from hil.transports import Transport, transport_pair

#: Every configuration that runs without hardware: (id, backend, options).
PAIRS = [
    ("inproc", "inproc", {}),
    ("udp", "udp", {}),
    ("serial-pty", "serial", {}),
    ("serial-loop", "serial", {"url": "loop://"}),
    ("can-fd", "can", {"fd": True}),
    ("can-classic", "can", {"fd": False}),
]


@pytest.fixture(params=PAIRS, ids=[p[0] for p in PAIRS])
def pair(request: pytest.FixtureRequest) -> Iterator[tuple[Transport, Transport]]:
    """(master, slave) of one backend configuration; closed afterwards."""
    _, name, options = request.param
    master, slave = transport_pair(name, **options)
    try:
        yield master, slave
    finally:
        master.close()
        slave.close()
