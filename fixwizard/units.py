"""Parsing of lengths typed by people ("1mm", "0.003 m", "3") into metres and of ages ("8h", "30d") into seconds,
and how far a robot and its tool reach."""

import math
import re

from fixwizard.errors import InputError

_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(mm|m)?\s*$")
_METRES_PER_UNIT = {"m": 1.0, "mm": 1e-3}
_DURATION = re.compile(r"^\s*([-+]?\d+(?:\.\d+)?)\s*(s|min|h|d)?\s*$")  # a sign: refused as not positive
_SECONDS = {"s": 1.0, "min": 60.0, "h": 3600.0, "d": 86400.0}
MAX_REACH_M = 20.0  # no robot arm reaches farther from its base: a position beyond is millimetres read as metres
MAX_TOOL_M = 2.0  # no tool holds its ball farther from the flange: a tip beyond is millimetres read as metres


def parse_length_m(text: str, default_unit: str = "m") -> float:
    """Parse a length such as ``"1mm"`` or ``"0.001"`` (``default_unit`` if no suffix); returns metres."""
    match = _LENGTH.match(str(text))
    if match is None:
        raise InputError(f"cannot read the length {text!r}: write a number with m or mm, e.g. 1mm or 0.001m")
    value = float(match.group(1)) * _METRES_PER_UNIT[match.group(2) or default_unit]
    if not math.isfinite(value):
        raise InputError(f"the length {text!r} is not a finite number")
    return value


def parse_duration_s(text: str) -> float:
    """A duration such as ``90``, ``90s``, ``30min``, ``8h`` or ``30d`` in seconds."""
    match = _DURATION.match(str(text))
    if match is None:
        raise InputError(f"cannot read the age {text!r}: write a number with s, min, h or d, e.g. 8h or 30d")
    seconds = float(match.group(1)) * _SECONDS[match.group(2) or "s"]
    if not math.isfinite(seconds) or seconds <= 0:
        raise InputError(f"the largest report age must be positive, not {text!r}")
    return seconds
