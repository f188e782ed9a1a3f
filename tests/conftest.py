"""Test-wide settings: no test touches the user's real database or data folder."""

import pytest


@pytest.fixture(autouse=True)
def _private_database(tmp_path, monkeypatch):
    monkeypatch.setenv("STICKSLIP_DB", str(tmp_path / "stickslip-test.db"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg-data"))
