"""A TCP port of the fake controller: accepts clients, runs one handler thread per client, and can drop every
client and stop listening (a pulled network cable) and listen again."""

import socket
import threading
from collections.abc import Callable


class Listener:
    """Serves ``handle(client_socket)`` on ``host:port`` while online."""

    def __init__(self, host: str, port: int, handle: Callable[[socket.socket], None]) -> None:
        self.host = host
        self.port = port
        self._handle = handle
        self._server: socket.socket | None = None
        self._clients: set[socket.socket] = set()
        self._lock = threading.Lock()

    def start(self) -> None:
        """Listen (nothing changes if it listens already)."""
        if self._server is not None:
            return
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            server.bind((self.host, self.port))
        except OSError as error:
            server.close()
            raise RuntimeError(f"port {self.port} on {self.host} is taken ({error.strerror}): another loopback "
                               "controller or UR tool is running; run these tests one session at a time") from error
        server.listen()
        self._server = server
        threading.Thread(target=self._accept, args=(server,), name=f"loopback-{self.port}", daemon=True).start()

    def stop(self) -> None:
        """Stop listening and close every client connection."""
        server, self._server = self._server, None
        if server is not None:
            _close(server)
        self.drop_clients()

    def drop_clients(self) -> None:
        """Close every client connection (and go on listening, if listening)."""
        with self._lock:
            clients, self._clients = self._clients, set()
        for client in clients:
            _close(client)

    def _accept(self, server: socket.socket) -> None:
        while True:
            try:
                client, _ = server.accept()
            except OSError:
                return
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._clients.add(client)
            threading.Thread(target=self._serve, args=(client,), name=f"loopback-{self.port}-client",
                             daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        try:
            self._handle(client)
        except OSError:
            pass
        finally:
            with self._lock:
                self._clients.discard(client)
            _close(client)


def _close(sock: socket.socket) -> None:
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    sock.close()
