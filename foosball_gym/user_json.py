"""JSON from files a user hands over (run configurations, session and system identification
logs): a damaged or hostile file is one :class:`ValueError` that says what is wrong, not a
``RecursionError`` from JSON nested a hundred thousand deep, nor seconds spent turning a
number of thousands of digits into an integer.
"""

from __future__ import annotations

import json
from typing import Any

#: Digits an integer in a user's file may have: far beyond any count, seed or size it holds.
MAX_INT_DIGITS = 30


def _integer(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {digits} digits (at most {MAX_INT_DIGITS})")
    return int(text)


def loads(text: str | bytes) -> Any:
    """``json.loads`` for a user's file.

    Raises:
        ValueError: not JSON, nested deeper than the interpreter's recursion allows, or an
            integer of more than :data:`MAX_INT_DIGITS` digits.
    """
    try:
        return json.loads(text, parse_int=_integer)
    except RecursionError:
        raise ValueError("JSON nested too deep to read") from None
