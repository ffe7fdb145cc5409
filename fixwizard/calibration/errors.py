"""Errors of the tool-tip calibration; each message says what to do next."""

from fixwizard.errors import InputError


class CalibrationError(InputError):
    """The recorded poses cannot give a trustworthy calibration (too few, degenerate or inconsistent)."""


class CalibrationFileError(InputError):
    """A stored tip calibration cannot be read (not YAML, another schema, missing or damaged values)."""
