"""Every stage's constants live in its parameter dataclass, with a unit and a reason, and the docs table is current."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, fields
from pathlib import Path

import pytest

from stickslip.audio.parameters import STAGES, markdown

PAGE = Path(__file__).resolve().parents[1] / "docs" / "audio-parameters.md"


def test_the_docs_table_is_generated_from_the_dataclasses() -> None:
    assert PAGE.read_text(encoding="utf-8") == markdown(), (
        "docs/audio-parameters.md is stale: python -m stickslip.audio.parameters > docs/audio-parameters.md"
    )


@pytest.mark.parametrize("cls", [c for _, classes in STAGES for c in classes], ids=lambda c: c.__name__)
def test_each_parameter_says_why_and_its_dataclass_is_frozen(cls: type) -> None:
    default = cls()
    for f in fields(cls):
        assert "unit" in f.metadata and len(f.metadata.get("why", "")) >= 15, f.name
        with pytest.raises(FrozenInstanceError):
            setattr(default, f.name, getattr(default, f.name))


def test_the_stages_hold_every_parameter_dataclass_once() -> None:
    classes = [c for _, cs in STAGES for c in cs]
    assert len(classes) == len(set(classes)) == 24
    assert sum(len(fields(c)) for c in classes) == markdown().count("\n| `")
