"""Sockets for the servers (the pilot server, the live station): a bad address or a port in use is one line."""

from __future__ import annotations

import socket

from vlnpilot.core.errors import ConfigError


def bind_socket(host: str, port: int, who: str) -> socket.socket:
    """A listening TCP socket on host:port (port 0: any free port); ConfigError naming `who` otherwise."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn does: a TIME_WAIT port is free
    try:
        sock.bind((host, port))
    except (OSError, OverflowError) as exc:
        sock.close()
        raise ConfigError(f"{who} cannot listen on {host}:{port} ({getattr(exc, 'strerror', None) or exc}); "
                          "choose another port, or another address") from None
    sock.listen(16)
    return sock


def check_port_free(host: str, port: int, who: str) -> None:
    """Bind and release host:port, so that a server started next does not fail there in its own words."""
    bind_socket(host, port, who).close()
