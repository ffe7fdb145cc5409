"""The dashboard server (29999): a greeting, then one reply line per command line."""

import socket
from collections.abc import Callable

DASHBOARD_PORT = 29999
GREETING = "Connected: Universal Robots Dashboard Server"


def serve_dashboard(client: socket.socket, reply: Callable[[str], str]) -> None:
    """Answer each newline-terminated command of ``client`` with ``reply(command)``."""
    client.sendall(f"{GREETING}\n".encode())
    pending = b""
    while chunk := client.recv(4096):
        pending += chunk
        while b"\n" in pending:
            line, pending = pending.split(b"\n", 1)
            client.sendall(f"{reply(line.decode().strip())}\n".encode())
