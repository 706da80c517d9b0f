"""What counts as a number in a link's text on the wire: a finite float, else why not.

The codecs (``kawasaki_codec``, ``rsi_codec``) wrap the reason in their own error, naming
the field it was read from."""

from __future__ import annotations

import math


def finite_float(text: str | bytes) -> float:
    """``text`` as a float; ValueError ``is not a number`` or ``is not finite`` otherwise."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError("is not a number") from None
    if not math.isfinite(value):
        raise ValueError("is not finite")
    return value
