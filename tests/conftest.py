"""Test-wide settings: no test touches the real database, data folder or config file, and none reads the calendar.

"Today" is pinned (``$STICKSLIP_TODAY``, read by :func:`stickslip.clock.today`), so the
suite gives the same answers on any date and in any time zone. The pinned day is the
session label of the synthetic tables in ``synth.py``: a calibration made from them is
today's, and tests that want an old calibration say so with an earlier label.
Subprocesses inherit the pin through the environment.

Property tests draw the same examples on every run (the ``repeatable`` hypothesis
profile: ``derandomize``), so a submission never passes or fails on a lucky draw; fresh
draws are a deliberate run, ``make test-explore`` (``STICKSLIP_HYPOTHESIS=explore``),
and a draw that breaks something is pinned as an ``@example`` where it is fixed.
"""

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings
from pinned import PINNED_TODAY  # tests/support: also read by the generators and benchmarks

settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("STICKSLIP_HYPOTHESIS", "repeatable"))



@pytest.fixture(autouse=True)
def _private_database(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STICKSLIP_DB", str(tmp_path / "stickslip-test.db"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg-data"))
    # no test reads the user's configuration file (docs/config.md): a path where none is
    monkeypatch.setenv("STICKSLIP_CONFIG", str(tmp_path / "no-config" / "config.toml"))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg-config"))


@pytest.fixture(autouse=True)
def _pinned_today(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STICKSLIP_TODAY", PINNED_TODAY)


@pytest.fixture()
def RE() -> Iterator[Any]:
    """A bluesky RunEngine for the bluesky tests (skips where the ``bluesky`` extra is missing), halted after."""
    bluesky = pytest.importorskip("bluesky")
    re = bluesky.RunEngine({}, call_returns_result=True)
    yield re
    if re.state != "idle":
        re.halt()
