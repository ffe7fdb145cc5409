"""Numbers as a UR controller's parsers read them: positional notation, no exponent, every digit kept."""

from decimal import Decimal


def positional(value: float) -> str:
    """``value`` with the digits of its shortest repr in positional notation: ``1.2e-05`` as ``0.000012``. Python
    writes exponents below 1e-4 and from 1e16, which neither URScript's manual nor the XML-RPC specification
    (doubles: digits, a point, digits) gives a form for; numpy's repr (``np.float64(0.02)``) is not a number at all."""
    return format(Decimal(repr(float(value))), "f")
