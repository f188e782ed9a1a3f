"""One field of a stage's parameter dataclass: its default, its unit and why it is what it is.

Every stage of the end-stop detector keeps its constants in one frozen dataclass
(``GuardParams``, ``DropParams``, ``PersistenceParams``, ...). Each field is declared
with :func:`param`, so the unit and the reason travel with the value; the table in
``docs/audio-parameters.md`` is generated from them (:mod:`stickslip.audio.parameters`).
"""

from __future__ import annotations

from dataclasses import Field, field, fields
from typing import Any, TypeVar

__all__ = ["ParamRow", "param", "rows"]

T = TypeVar("T")


def param(default: T, unit: str, why: str) -> T:
    """A dataclass field with ``default``, its ``unit`` ("" when dimensionless) and a one-line reason ``why``."""
    return field(default=default, metadata={"unit": unit, "why": why})


ParamRow = tuple[str, Any, str, str]


def rows(cls: type[Any]) -> list[ParamRow]:
    """(name, default, unit, reason) of every field of the parameter dataclass ``cls``."""
    out: list[ParamRow] = []
    f: Field[Any]
    for f in fields(cls):
        out.append((f.name, f.default, str(f.metadata.get("unit", "")), str(f.metadata.get("why", ""))))
    return out
