"""The user's configuration file: default device, calibration, database, geometry and calibration age.

A TOML file (docs/config.md) in the platform's configuration folder
(:func:`default_config_path`: ``~/.config/stickslip/config.toml`` on Linux,
``~/Library/Application Support/stickslip/config.toml`` on macOS,
``%LOCALAPPDATA%\\stickslip\\config.toml`` on Windows), or wherever
``$STICKSLIP_CONFIG`` points::

    device = "mm3a:///dev/ttyUSB0"      # the controller the device commands drive
    calibration = "cal/today.json"      # relative paths: from this file's folder
    database = "~/lab/stickslip.db"    # or a shared one: "postgresql://rig1@labdb/stickslip"
    max_age_days = 1                    # a calibration this many days old is still fresh

    [geometry]                          # the arm (docs/taskspace.md): lengths with units
    offset = "0mm"
    length = "23.5mm"

Only the command line reads it, and every command-line option wins over it (and so
does an environment variable that existed before it: ``$STICKSLIP_DB``,
``$STICKSLIP_MAX_AGE_DAYS``); the library below the command line takes explicit
arguments. A missing file is no error (built-in defaults apply); anything else that
is wrong — TOML that does not parse, an unknown key, a value of the wrong kind, a
password in the device URL — raises :class:`ConfigError`, one line naming the file,
the line where it can tell, and the key. A password is never stored here: a config
file is plain text in the home folder, and the ANC300's comes from
``$STICKSLIP_ANC300_PASSWORD`` (docs/threat-model.md).

This module imports no numpy: the command line reads the file before it knows whether
a command needs the numerical layers.
"""

from __future__ import annotations

import difflib
import math
import os
import re
import tomllib
import unicodedata
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from .devices.base import BACKENDS, redact_url
from .records import FILE_URL_DATABASE, atomic_write_text, is_file_url, read_text_bounded
from .units import UnitError, parse_length

__all__ = [
    "ENV_CONFIG",
    "FILE_NAME",
    "KEYS",
    "MAX_CONFIG_BYTES",
    "ConfigError",
    "UserConfig",
    "config_path",
    "default_config_path",
    "load_config",
    "parse_config",
    "template",
    "write_template",
]

ENV_CONFIG = "STICKSLIP_CONFIG"
"""Environment variable with the path of the configuration file (overrides the platform's folder)."""
FILE_NAME = "config.toml"
"""The file's name in the platform's configuration folder."""
MAX_CONFIG_BYTES = 256 * 1024
"""Largest configuration file read (bytes); a real one is a few hundred."""
MAX_AGE_LIMIT = 36500
"""Largest ``max_age_days`` accepted (100 years), as for ``--max-age``."""

KEYS: dict[str, str] = {
    "device": "the controller URL the device commands use without --device (no password)",
    "calibration": "the calibration JSON used without --calibration",
    "database": "the database used without --db (after $STICKSLIP_DB): an SQLite file or a postgresql:// URL",
    "max_age_days": "the age in days up to which a calibration is fresh (after --max-age, $STICKSLIP_MAX_AGE_DAYS)",
    "geometry.offset": "joint-1 axis to joint-2 axis (a length: 0mm), used without --geometry",
    "geometry.length": "joint-2 axis to the tip at q3 = 0 (a length: 21mm), used without --geometry",
}
"""Every key the file may hold (dotted for ``[geometry]``), with what it sets."""

_TABLES = {"geometry"}

DATABASE_SCHEMES = ("postgresql", "postgres")
"""URL schemes the ``database`` key takes (as :data:`stickslip.storage.POSTGRES_SCHEMES`; a test keeps them equal)."""


def _has_password(url: str) -> bool:
    """Whether a URL carries a password: ``user:PASSWORD@`` (before the last ``@``), or a ``...pass...=`` option."""
    rest = url.partition("://")[2]
    main, _, query = rest.partition("?")
    userinfo, at, _ = main.rpartition("@")
    if at and ":" in userinfo:
        return True
    return redact_url(url) != url or any(
        "pass" in opt.partition("=")[0].lower() for opt in query.split("&") if "=" in opt
    )


class ConfigError(ValueError):
    """The configuration file cannot be used: one line naming the file, the line and the key."""


@dataclass(frozen=True)
class UserConfig:
    """What the configuration file says; ``None`` for every key it does not set.

    Attributes
    ----------
    path : Path
        The file it was read from, or looked for (absolute).
    found : bool
        Whether the file exists (a missing file sets nothing).
    device : str or None
        Default controller URL (``mm3a:///dev/ttyUSB0``); never holds a password.
    calibration : Path or None
        Default calibration JSON, absolute (a relative path in the file is read from
        the file's folder; ``~`` is the home folder).
    database : Path or str or None
        Default database: an SQLite file, absolute (as ``calibration``), or a shared
        PostgreSQL database's ``postgresql://`` URL (``str``; never holds a password).
    max_age_days : int or None
        Largest age of a calibration, days (0..36500), still used without a warning.
    geometry_offset : float or None
        Distance from joint 1's axis to joint 2's axis, m (``[geometry] offset``).
    geometry_length : float or None
        Distance from joint 2's axis to the tip at ``q3 = 0``, m (``[geometry] length``).
    """

    path: Path
    found: bool = False
    device: str | None = None
    calibration: Path | None = None
    database: Path | str | None = None
    max_age_days: int | None = None
    geometry_offset: float | None = None
    geometry_length: float | None = None

    def values(self) -> dict[str, object]:
        """``{dotted key: value}`` of the keys the file sets (paths as strings, lengths in m)."""
        out: dict[str, object] = {
            "device": self.device,
            "calibration": None if self.calibration is None else str(self.calibration),
            "database": None if self.database is None else str(self.database),
            "max_age_days": self.max_age_days,
            "geometry.offset": self.geometry_offset,
            "geometry.length": self.geometry_length,
        }
        return {k: v for k, v in out.items() if v is not None}


def default_config_path() -> Path:
    """The platform's place for the file: ``platformdirs.user_config_path("stickslip") / "config.toml"``.

    ``$XDG_CONFIG_HOME/stickslip`` or ``~/.config/stickslip`` on Linux,
    ``~/Library/Application Support/stickslip`` on macOS, ``%LOCALAPPDATA%\\stickslip``
    on Windows.
    """
    import platformdirs

    return platformdirs.user_config_path("stickslip", appauthor=False) / FILE_NAME


def config_path() -> Path:
    """Where the file is looked for: ``$STICKSLIP_CONFIG`` if set (and not empty), else :func:`default_config_path`.

    Always absolute (a relative ``$STICKSLIP_CONFIG`` is taken from the working folder).
    """
    env = os.environ.get(ENV_CONFIG, "")
    p = Path(env).expanduser() if env.strip() else default_config_path()
    return Path(os.path.abspath(p))


def load_config(path: str | os.PathLike[str] | None = None) -> UserConfig:
    """Read the configuration file at ``path`` (default :func:`config_path`).

    A file that does not exist sets nothing (``found=False``); it is not an error.

    Raises
    ------
    ConfigError
        One line: the file (and line) and what is wrong — not a regular file, too large,
        not UTF-8, not TOML, an unknown key (with the nearest known one), a value of the
        wrong kind or out of range, a password in the device URL (never echoed).
    """
    p = Path(os.path.abspath(Path(path).expanduser())) if path is not None else config_path()
    try:
        os.stat(p)
    except FileNotFoundError:
        return UserConfig(path=p, found=False)
    except OSError:
        pass  # read_text_bounded says what is wrong
    try:
        text = read_text_bounded(p, "config", MAX_CONFIG_BYTES)
    except ValueError as e:
        raise ConfigError(str(e)) from None
    return parse_config(text, p)


_TOML_WHERE = re.compile(
    r"^(?P<reason>.*?)\s*\(at (?:line (?P<line>\d+), column (?P<col>\d+)|end of document)\)$", re.S
)


def parse_config(text: str, path: Path) -> UserConfig:
    """The :class:`UserConfig` that TOML ``text`` (the file at ``path``) describes.

    Relative paths are taken from ``path``'s folder. Raises :class:`ConfigError` as
    :func:`load_config` does.
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = _TOML_WHERE.match(str(e))
        if m is None:  # pragma: no cover - every tomllib message ends with its place
            raise ConfigError(f"{path}: not TOML: {e}") from None
        line = m.group("line") or str(max(1, len(text.splitlines())))
        where = f"{line}:{m.group('col')}" if m.group("col") else line
        raise ConfigError(f"{path}:{where}: not TOML: {m.group('reason')}") from None
    return _Reader(text, path).read(doc)


class _Reader:
    """Checks a parsed document key by key; every problem names the file, its line and the key."""

    def __init__(self, text: str, path: Path) -> None:
        self.text = text
        self.path = path

    def fail(self, key: str, message: str) -> ConfigError:
        line = _line_of(self.text, tuple(key.split(".")))
        where = f"{self.path}:{line}" if line else str(self.path)
        return ConfigError(f"{where}: {key}: {message}")

    def read(self, doc: dict[str, object]) -> UserConfig:
        known = [k for k in KEYS if "." not in k] + sorted(_TABLES)
        for key in doc:
            if key not in known:
                raise self._unknown(key, known)
        geometry = doc.get("geometry", {})
        if not isinstance(geometry, dict):
            raise self.fail("geometry", f"must be a table ([geometry] with offset and length), got {_kind(geometry)}")
        sub = [k.split(".", 1)[1] for k in KEYS if k.startswith("geometry.")]
        for key in geometry:
            if key in known and key not in sub:  # a top-level key written below the [geometry] header
                line = _line_of(self.text, ("geometry", key))
                where = f"{self.path}:{line}" if line else str(self.path)
                raise ConfigError(
                    f"{where}: {key} is inside [geometry] here: move it above the [geometry] line "
                    "(keys after a [table] header belong to that table)"
                )
            if key not in sub:
                raise self._unknown(f"geometry.{key}", [f"geometry.{k}" for k in sub])
        return UserConfig(
            path=self.path,
            found=True,
            device=self._device(doc.get("device")),
            calibration=self._path("calibration", doc.get("calibration")),
            database=self._database(doc.get("database")),
            max_age_days=self._days(doc.get("max_age_days")),
            geometry_offset=self._length("geometry.offset", geometry.get("offset")),
            geometry_length=self._length("geometry.length", geometry.get("length")),
        )

    def _unknown(self, key: str, known: list[str]) -> ConfigError:
        near = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
        hint = f"did you mean {near[0]!r}? " if near else ""
        shown = key if len(key) <= 60 else key[:57] + "..."
        line = _line_of(self.text, tuple(key.split(".")))
        where = f"{self.path}:{line}" if line else str(self.path)
        return ConfigError(f"{where}: unknown key {shown!r} ({hint}known: {', '.join(sorted(known))})")

    def _string(self, key: str, value: object, what: str) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string ({what}), got {_kind(value)}")
        if not value.strip():
            raise self.fail(key, f"is empty: give {what}, or leave the key out")
        if any(unicodedata.category(c) == "Cc" for c in value):
            raise self.fail(key, f"holds a control character: give {what}")
        return value.strip()

    def _device(self, value: object) -> str | None:
        if value is None:
            return None
        url = self._string("device", value, "a device URL such as mm3a:///dev/ttyUSB0")
        if redact_url(url) != url:
            raise self.fail(
                "device",
                "a password in the device URL is refused (a config file is plain text others may read): "
                "remove it and set it in the environment, $STICKSLIP_ANC300_PASSWORD for an ANC300 "
                "(docs/threat-model.md)",
            )
        try:
            parts = urlsplit(url)
            parts.port  # noqa: B018  (a port that is not a number raises here)
        except ValueError as e:
            raise self.fail("device", f"malformed device URL {url!r}: {e}") from None
        scheme = parts.scheme
        if not scheme or "://" not in url:
            raise self.fail("device", f"{url!r} names no backend: write scheme://..., e.g. mm3a://{url}, sim://")
        if scheme not in BACKENDS and scheme.split("+", 1)[0] not in BACKENDS:
            near = difflib.get_close_matches(scheme, list(BACKENDS), n=1)
            hint = f"did you mean {near[0]}://? " if near else ""
            raise self.fail("device", f"unknown device scheme {scheme}:// ({hint}known: {', '.join(sorted(BACKENDS))})")
        return url

    def _database(self, value: object) -> Path | str | None:
        """An SQLite file (as ``calibration``), or a ``postgresql://`` URL without a password."""
        if value is None:
            return None
        text = self._string("database", value, "a file path or a postgresql:// URL")
        head, sep, _ = text.partition("://")
        if is_file_url(text) and not sep:
            raise self.fail("database", FILE_URL_DATABASE)
        if not sep or len(head) < 2:  # a path (a one-letter "scheme" is a Windows drive)
            return self._path("database", text)
        if head.lower() not in DATABASE_SCHEMES:
            raise self.fail(
                "database", f"{head}:// is not a database stickslip can use: give a file path or a postgresql:// URL"
            )
        if _has_password(text):
            raise self.fail(
                "database",
                "a password in the database URL is refused (a config file is plain text others may read): "
                "remove it and give it in $PGPASSWORD or ~/.pgpass (docs/storage.md)",
            )
        return text

    def _path(self, key: str, value: object) -> Path | None:
        if value is None:
            return None
        p = Path(self._string(key, value, "a file path")).expanduser()
        return p if p.is_absolute() else Path(os.path.abspath(self.path.parent / p))

    def _days(self, value: object) -> int | None:
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail("max_age_days", f"must be a whole number of days, got {_kind(value)}")
        if not 0 <= value <= MAX_AGE_LIMIT:
            raise self.fail("max_age_days", f"must be 0..{MAX_AGE_LIMIT} days, got {value}")
        return value

    def _length(self, key: str, value: object) -> float | None:
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise self.fail(key, f"must be a length (\"21mm\", or a number in metres), got {_kind(value)}")
        try:
            v = parse_length(value) if isinstance(value, str) else float(value)
        except UnitError as e:
            raise self.fail(key, str(e)) from None
        except (ArithmeticError, ValueError) as e:  # pi/0, 1e999
            raise self.fail(key, f"{value!r} is not a usable length ({e})") from None
        if not math.isfinite(v):
            raise self.fail(key, f"{value!r} is not a finite length")
        return v


def _kind(value: object) -> str:
    """How TOML calls a value's type, for messages (the value itself is not shown)."""
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
             dict: "a table"}
    for t, name in names.items():
        if isinstance(value, t):
            return name
    return "a date or time"


_HEADER = re.compile(r"^\s*\[\[?\s*(?P<name>[^\[\]]+?)\s*\]\]?\s*(?:#.*)?$")
_KEY_PART = r"(?:\"[^\"]*\"|'[^']*'|[A-Za-z0-9_\-]+)"
_KEY_LINE = re.compile(r"^\s*(?P<key>" + _KEY_PART + r"(?:\s*\.\s*" + _KEY_PART + r")*)\s*=")


def _key_path(raw: str) -> tuple[str, ...]:
    parts = re.findall(r"\"([^\"]*)\"|'([^']*)'|([A-Za-z0-9_\-]+)", raw)
    return tuple(a or b or c for a, b, c in parts)


def _line_of(text: str, key: tuple[str, ...]) -> int | None:
    """The first line that sets ``key`` (or opens its table), best effort; ``None`` if not found."""
    table: tuple[str, ...] = ()
    for n, line in enumerate(text.splitlines(), start=1):
        m = _HEADER.match(line)
        if m:
            table = _key_path(m.group("name"))
            if table[: len(key)] == key:
                return n
            continue
        m = _KEY_LINE.match(line)
        if m and (table + _key_path(m.group("key")))[: len(key)] == key:
            return n
    return None


_TEMPLATE = """\
# stickslip configuration (docs/config.md). Every command-line option wins over this
# file, and so do $STICKSLIP_DB and $STICKSLIP_MAX_AGE_DAYS. Remove the "# " before a
# line to set it. Relative paths are read from this file's folder; ~ is your home.
# `stickslip config show` prints what each command would use, and where it came from.

# The controller that move, where, reach, jog, traverse and record drive without
# --device. Never a password here: an ANC300's comes from $STICKSLIP_ANC300_PASSWORD.
# device = "mm3a:///dev/ttyUSB0"

# The calibration used without --calibration (move, reach, jog, predict, validate,
# plan, show).
# calibration = "calibration.json"

# The database of traverses, calibrations and positions, used without --db: a file, or a shared
# PostgreSQL database (postgresql://USER@HOST/DBNAME; the password in $PGPASSWORD or ~/.pgpass).
# database = "stickslip.db"

# A calibration up to this many days old is used without a recalibration warning
# (0: only today's).
# max_age_days = 0

# The arm's geometry for reach and jog, without --geometry (docs/taskspace.md):
# lengths with units (mm, um) or numbers in metres.
# [geometry]
# offset = "0mm"     # joint-1 axis to joint-2 axis
# length = "21mm"    # joint-2 axis to the tip with joint 3 retracted
"""


def template() -> str:
    """The commented template ``stickslip config init`` writes: every key, none set."""
    return _TEMPLATE


def write_template(path: str | os.PathLike[str] | None = None, force: bool = False) -> Path:
    """Write :func:`template` to ``path`` (default :func:`config_path`), creating its folder.

    The write is atomic (a temporary file, then a rename). Raises ``FileExistsError``
    if the file exists and ``force`` is false, ``OSError`` if it cannot be written.
    Returns the path written.
    """
    p = Path(os.path.abspath(Path(path).expanduser())) if path is not None else config_path()
    if p.exists() and not force:
        raise FileExistsError(f"{p} exists: keep it, or overwrite it with --force")
    if p.exists() and not p.is_file():
        raise IsADirectoryError(f"{p} is not a regular file: not overwritten")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:  # a file where a folder should be, no permission
        raise OSError(f"cannot create the folder {p.parent} ({e.strerror or e})") from None
    return atomic_write_text(p, _TEMPLATE)
