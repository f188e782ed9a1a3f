"""Test-wide settings: no test touches the real database, data folder or config file, and none reads the calendar.

The storage tests run against both backends through the ``db`` fixture: an SQLite file,
and a schema of its own in a throwaway PostgreSQL server (``tests/support/pgserver.py``:
one per test process, started at the first test that needs it, stopped at the end;
skipped, with the reason, where PostgreSQL's binaries or psycopg are missing).

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

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import pytest
import tuned
import typer
import typer.testing
from hypothesis import settings
from pinned import PINNED_TODAY  # tests/support: also read by the generators and benchmarks

if TYPE_CHECKING:
    from pgserver import PostgresServer

settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("STICKSLIP_HYPOTHESIS", "repeatable"))


_C = TypeVar("_C")


def _built_once(get_command: Callable[[typer.Typer], _C]) -> Callable[[typer.Typer], _C]:
    """typer's ``get_command``, each app's click command built once: ``CliRunner.invoke`` rebuilds the whole command
    tree from the functions' signatures on every call (about 23 ms, a thousand fuzzed invocations a file). The tree
    depends only on the app's registered functions, fixed when the modules are imported, and click keeps each
    invocation's state in its own context, so the same tree serves every invocation."""
    built: dict[int, tuple[typer.Typer, _C]] = {}

    def get(app: typer.Typer) -> _C:
        kept = built.get(id(app))
        if kept is None or kept[0] is not app:
            kept = built[id(app)] = (app, get_command(app))
        return kept[1]

    return get


def pytest_configure(config: pytest.Config) -> None:
    """The CLI's command tree built once per test process (:func:`_built_once`), and the session's folder of kept
    tunings (``tests/support/tuned.py``), made by the process that starts the xdist workers, which inherit its name
    through the environment; removed at the session's end."""
    typer.testing._get_command = _built_once(typer.testing._get_command)  # type: ignore[assignment,attr-defined]
    if not hasattr(config, "workerinput") and tuned.ENV not in os.environ:
        os.environ[tuned.ENV] = tempfile.mkdtemp(prefix="stickslip-tunings-")
        config.stash[_TUNINGS] = os.environ[tuned.ENV]


def pytest_unconfigure(config: pytest.Config) -> None:
    folder = config.stash.get(_TUNINGS, None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
        os.environ.pop(tuned.ENV, None)


_TUNINGS = pytest.StashKey[str]()



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


# ---------------------------------------------------------------- the two storage backends


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[PostgresServer]:
    """A PostgreSQL server of this test process (skips with the reason where none can be started)."""
    import pgserver

    try:
        server = pgserver.start()
    except pgserver.Unavailable as e:
        pytest.skip(f"no PostgreSQL server: {e}")
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture()
def postgres_url(postgres_server: PostgresServer, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """The URL of a new empty schema; the password in ``$PGPASSWORD`` (as docs/storage.md advises), not the URL.

    No ``PG*`` variable of the machine reaches libpq, and ``~/.pgpass`` is never read.
    """
    for k in [k for k in os.environ if k.startswith("PG")]:
        monkeypatch.delenv(k)
    monkeypatch.setenv("PGPASSFILE", str(tmp_path / "no-pgpass"))
    monkeypatch.setenv("PGPASSWORD", postgres_server.password)
    return postgres_server.url(postgres_server.new_schema())


@pytest.fixture(params=["sqlite", "postgresql"])
def db(request: pytest.FixtureRequest, tmp_path: Path) -> Path | str:
    """Where a test keeps its database, once per backend: an SQLite file, then a PostgreSQL URL."""
    if request.param == "sqlite":
        return tmp_path / "s.db"
    url: str = request.getfixturevalue("postgres_url")
    return url
