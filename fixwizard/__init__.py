"""fixwizard: fixture pose calibration with guaranteed bounds from a few robot taps."""

__version__ = "0.1.0"
