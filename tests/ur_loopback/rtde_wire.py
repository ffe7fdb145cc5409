"""RTDE protocol v2 on the wire, as in Universal Robots' RTDE guide: packet framing, package types and the
types of the fields a client may subscribe to or write."""

import socket
import struct

HEADER = struct.Struct(">HB")  # packet size including the header, package type
PROTOCOL_VERSION = 2

REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")

# struct format of each RTDE data type (network byte order is added when packing)
TYPE_FORMATS = {"BOOL": "?", "UINT8": "B", "UINT32": "I", "UINT64": "Q", "INT32": "i", "DOUBLE": "d",
                "VECTOR3D": "3d", "VECTOR6D": "6d", "VECTOR6INT32": "6i", "VECTOR6UINT32": "6I"}

_NAMED_TYPES = {
    "timestamp": "DOUBLE", "target_q": "VECTOR6D", "target_qd": "VECTOR6D", "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D", "target_moment": "VECTOR6D", "actual_q": "VECTOR6D", "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D", "actual_current_window": "VECTOR6D", "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D", "actual_TCP_speed": "VECTOR6D", "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D", "target_TCP_speed": "VECTOR6D", "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D", "actual_execution_time": "DOUBLE", "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32", "safety_mode": "INT32", "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D", "speed_scaling": "DOUBLE", "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE", "actual_main_voltage": "DOUBLE", "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE", "actual_joint_voltage": "VECTOR6D", "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32", "elbow_position": "VECTOR3D", "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32", "safety_status_bits": "UINT32", "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE", "standard_analog_input1": "DOUBLE", "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE", "io_current": "DOUBLE", "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32", "tool_analog_input0": "DOUBLE", "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32", "tool_output_current": "DOUBLE", "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE", "ft_raw_wrench": "VECTOR6D", "payload": "DOUBLE", "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D", "script_control_line": "UINT32", "external_force_torque": "VECTOR6D",
    "output_bit_registers0_to_31": "UINT32", "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    # inputs the RTDE I/O interface sets up
    "standard_digital_output_mask": "UINT8", "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8", "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8", "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE", "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
}


def field_type(name: str) -> str:
    """The RTDE type of a field, or ``NOT_FOUND`` as the controller answers for an unknown name."""
    if name in _NAMED_TYPES:
        return _NAMED_TYPES[name]
    prefix, _, index = name.rpartition("_")
    if index.isdigit() and 0 <= int(index) <= 47:
        if prefix in ("input_int_register", "output_int_register"):
            return "INT32"
        if prefix in ("input_double_register", "output_double_register"):
            return "DOUBLE"
    if index.isdigit() and 64 <= int(index) <= 127 and prefix in ("input_bit_register", "output_bit_register"):
        return "BOOL"
    return "NOT_FOUND"


def recipe_struct(types: list[str]) -> struct.Struct:
    """The big-endian layout of a data package body (without its recipe id) for fields of ``types``."""
    return struct.Struct(">" + "".join(TYPE_FORMATS[t] for t in types))


def flatten(values: list) -> list:
    """Field values as the flat argument list ``struct.pack`` needs (vectors expanded)."""
    flat = []
    for value in values:
        flat.extend(value if isinstance(value, (list, tuple)) else (value,))
    return flat


def unflatten(types: list[str], flat: tuple) -> list:
    """The inverse of ``flatten`` for fields of ``types``."""
    values, index = [], 0
    for field in types:
        count = int(TYPE_FORMATS[field][:-1] or 1)
        values.append(flat[index] if count == 1 else list(flat[index:index + count]))
        index += count
    return values


def pack(package_type: int, payload: bytes = b"") -> bytes:
    """One framed packet."""
    return HEADER.pack(HEADER.size + len(payload), package_type) + payload


def read_packet(sock: socket.socket) -> tuple[int, bytes]:
    """The next packet's type and payload; raises ``ConnectionError`` when the peer has closed."""
    size, package_type = HEADER.unpack(_read_exactly(sock, HEADER.size))
    return package_type, _read_exactly(sock, size - HEADER.size)


def _read_exactly(sock: socket.socket, count: int) -> bytes:
    data = b""
    while len(data) < count:
        chunk = sock.recv(count - len(data))
        if not chunk:
            raise ConnectionError("the RTDE client closed the connection")
        data += chunk
    return data
