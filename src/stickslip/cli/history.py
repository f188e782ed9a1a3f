"""Commands of this area are added here (see stickslip.cli)."""

from __future__ import annotations

from . import app  # noqa: F401
