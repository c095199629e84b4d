"""Where the live view listens: ``[HOST:]PORT``, on the loopback interface unless a host is given."""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass

DEFAULT_HOST = '127.0.0.1'
DEFAULT_PORT = 8765


@dataclass(frozen=True)
class Endpoint:
    """A host (name or address) and a TCP port (0 = any free port)."""

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT

    @property
    def loopback(self) -> bool:
        """True when every address ``host`` resolves to is a loopback address."""
        return is_loopback(self.host)


def parse_endpoint(text: str) -> Endpoint:
    """``PORT``, ``HOST:PORT`` or ``HOST`` (``[::1]:PORT`` for IPv6) -> :class:`Endpoint`; a missing host is
    127.0.0.1, a missing port 8765. Raises ValueError with what is wrong."""
    text = text.strip()
    if not text:
        return Endpoint()
    if text.isdigit():
        host, port_text = DEFAULT_HOST, text
    elif text.startswith('['):
        host, _, rest = text[1:].partition(']')
        port_text = rest[1:] if rest.startswith(':') else str(DEFAULT_PORT)
    elif text.count(':') == 1:
        host, port_text = text.split(':')
    else:
        host, port_text = text, str(DEFAULT_PORT)
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise ValueError(f'{text!r}: the port must be a number within [0, 65535] (expected [HOST:]PORT)')
    if not host:
        raise ValueError(f'{text!r}: empty host (expected [HOST:]PORT, e.g. 127.0.0.1:8765)')
    return Endpoint(host, int(port_text))


def is_loopback(host: str) -> bool:
    """True when ``host`` (a name or an address) resolves only to loopback addresses."""
    try:
        infos = socket.getaddrinfo(host, None)
    except socket.gaierror:
        return False
    return bool(infos) and all(ipaddress.ip_address(info[4][0].split('%')[0]).is_loopback for info in infos)
