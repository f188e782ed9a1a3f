"""Core commands: calibrate, predict, validate, plan, show."""

from __future__ import annotations

from . import app  # noqa: F401
