"""The kinds of a run's configuration fields as config.json holds them."""

from __future__ import annotations

from typing import Any

# How config.json spells each kind of field (by its annotation), and what it must hold.
KINDS_SPELLED = {
    "str": "a string",
    "int": "a whole number",
    "int | None": "a whole number or null",
    "float": "a number",
    "float | None": "a number or null",
    "bool": "true or false",
    "bool | None": "true, false or null",
    "tuple[int, ...]": "a list of whole numbers",
    "dict[str, Any]": "an object",
}


def of_kind(value: Any, kind: str) -> bool:
    """Whether ``value``, read from JSON, is of the field kind ``kind`` (an annotation)."""

    def whole(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool)

    if kind.endswith(" | None") and value is None:
        return True
    kind = kind.removesuffix(" | None")
    if kind == "int":
        return whole(value)
    if kind == "float":
        return whole(value) or isinstance(value, float)
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "str":
        return isinstance(value, str)
    if kind == "tuple[int, ...]":
        return isinstance(value, list) and all(whole(v) for v in value)
    return isinstance(value, dict)
