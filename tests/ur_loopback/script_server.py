"""The controller's script port (30003): it runs every complete program a client sends."""

import re
import socket
from collections.abc import Callable

SCRIPT_PORT = 30003
# a program is complete once its top-level ``def`` is closed by an ``end`` at the start of a line
_PROGRAM = re.compile(rb"^def \w+\(\):\n.*?^end\n?", re.DOTALL | re.MULTILINE)


def serve_scripts(client: socket.socket, run_program: Callable[[str], None]) -> None:
    """Read programs from ``client`` until it disconnects, handing each complete one to ``run_program``."""
    pending = b""
    while chunk := client.recv(65536):
        pending += chunk
        while (match := _PROGRAM.search(pending)) is not None:
            run_program(match.group(0).decode())
            pending = pending[match.end():]
