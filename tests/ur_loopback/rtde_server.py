"""The RTDE interface (30004), protocol v2: version negotiation, output recipes streamed at the requested
frequency, input recipes written into the controller's registers. Output and input recipe ids are counted
separately per client, each starting at 1."""

import socket
import struct
import threading
import time
from collections.abc import Callable

from ur_loopback import rtde_wire as wire

RTDE_PORT = 30004
MAX_STREAM_HZ = 250.0  # enough for ur_rtde's handshakes, light on a shared CPU


class RtdeSession:
    """One RTDE client connection."""

    def __init__(self, client: socket.socket, version: tuple[int, int, int, int],
                 read_outputs: Callable[[list[str]], list], write_inputs: Callable[[dict], None],
                 claim_inputs: Callable[[object, list[str]], bool], release_inputs: Callable[[object], None],
                 paused: Callable[[], bool] = lambda: False, burst_s: Callable[[], float] = lambda: 0.0) -> None:
        self._client = client
        self._version = version
        self._read_outputs = read_outputs
        self._write_inputs = write_inputs
        self._claim_inputs = claim_inputs
        self._release_inputs = release_inputs
        self._paused = paused  # while true no data goes out (a frozen link)
        self._burst_s = burst_s  # data sampled at the stream's rate goes out in bursts this far apart (s; 0: each)
        self._send_lock = threading.Lock()
        self._outputs: tuple[int, list[str], struct.Struct, float] | None = None
        self._inputs: dict[int, tuple[list[str], list[str], struct.Struct]] = {}
        self._streaming = threading.Event()
        self._closed = threading.Event()

    def serve(self) -> None:
        """Handle requests until the client disconnects."""
        threading.Thread(target=self._stream, name="loopback-rtde-stream", daemon=True).start()
        try:
            while True:
                package_type, payload = wire.read_packet(self._client)
                self._handle(package_type, payload)
        except ConnectionError:
            pass
        finally:
            self._closed.set()
            self._release_inputs(self)

    def _handle(self, package_type: int, payload: bytes) -> None:
        if package_type == wire.REQUEST_PROTOCOL_VERSION:
            (version,) = struct.unpack(">H", payload)
            self._send(wire.REQUEST_PROTOCOL_VERSION, bytes([version == wire.PROTOCOL_VERSION]))
        elif package_type == wire.GET_URCONTROL_VERSION:
            self._send(wire.GET_URCONTROL_VERSION, struct.pack(">IIII", *self._version))
        elif package_type == wire.SETUP_OUTPUTS:
            (frequency,) = struct.unpack(">d", payload[:8])
            names = _names(payload[8:])
            types = [wire.field_type(name) for name in names]
            recipe_id = 1 if self._outputs is None else self._outputs[0] + 1
            if "NOT_FOUND" not in types:
                self._outputs = (recipe_id, names, wire.recipe_struct(types), min(frequency, MAX_STREAM_HZ))
            self._send(wire.SETUP_OUTPUTS, bytes([recipe_id]) + ",".join(types).encode())
        elif package_type == wire.SETUP_INPUTS:
            names = _names(payload)
            types = [wire.field_type(name) for name in names]
            if "NOT_FOUND" not in types and not self._claim_inputs(self, names):
                types = ["IN_USE" if name.startswith("input_") else t for name, t in zip(names, types, strict=True)]
            recipe_id = len(self._inputs) + 1
            if "NOT_FOUND" not in types and "IN_USE" not in types:
                self._inputs[recipe_id] = (names, types, wire.recipe_struct(types))
            self._send(wire.SETUP_INPUTS, bytes([recipe_id if recipe_id in self._inputs else 0])
                       + ",".join(types).encode())
        elif package_type == wire.START:
            self._send(wire.START, bytes([self._outputs is not None]))
            if self._outputs is not None:
                self._streaming.set()
        elif package_type == wire.PAUSE:
            self._streaming.clear()
            self._send(wire.PAUSE, b"\x01")
        elif package_type == wire.DATA_PACKAGE:
            names, types, layout = self._inputs[payload[0]]
            values = wire.unflatten(types, layout.unpack(payload[1:]))
            self._write_inputs(dict(zip(names, values, strict=True)))

    def _stream(self) -> None:
        held: list[bytes] = []  # data packages sampled but not sent yet (a burst)
        held_since = time.monotonic()
        while not self._closed.is_set():
            if not self._streaming.wait(0.05) or self._paused():
                time.sleep(0.01)
                continue
            recipe_id, names, layout, frequency = self._outputs
            started = time.monotonic()
            body = layout.pack(*wire.flatten(self._read_outputs(names)))
            held.append(wire.pack(wire.DATA_PACKAGE, bytes([recipe_id]) + body))
            if started - held_since >= self._burst_s():
                try:
                    with self._send_lock:
                        self._client.sendall(b"".join(held))
                except OSError:
                    return
                held, held_since = [], started
            time.sleep(max(1.0 / frequency - (time.monotonic() - started), 0.0))

    def _send(self, package_type: int, payload: bytes) -> None:
        with self._send_lock:
            self._client.sendall(wire.pack(package_type, payload))


def _names(payload: bytes) -> list[str]:
    """Field names of a setup request; ur_rtde ends the list with a comma."""
    return [name for name in payload.decode().split(",") if name]
