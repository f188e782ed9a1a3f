"""Validated file loading and safe file writing: the boundary between files and the library.

Every file the toolkit reads goes through :func:`read_text_bounded` (regular files
only, a size limit, UTF-8) or, where it streams a table, :func:`text_lines` (the same
checks, no size limit), and every JSON document through :func:`read_json_text`
(also a nesting-depth limit and no ``NaN``/``Infinity``), so a folder, a FIFO,
``/dev/zero``, a huge or deeply nested file ends in one ``ValueError`` naming the file
and the reason, never a hang or a ``RecursionError``. :func:`check_calibration_dict`
checks a calibration document's physical ranges (``0 <= b < 1``, finite step sizes of
the right scale for each joint) before it is turned into a model, so a file written in
nanometres where metres are expected is refused with the reason instead of planned with.

:func:`atomic_write` writes an output file through a temporary file in the same
folder, flushed and synced, then ``os.replace``: a failed write leaves the old file as it
was and says so (:class:`WriteError`); a folder, FIFO or device is never written into
(:func:`writable_target`), nor read from (:func:`regular_file`).

This module imports only the standard library (it sits below every other layer).
"""

from __future__ import annotations

import contextvars
import errno
import io
import json
import math
import os
import re
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .joints import joint_spec

MAX_JSON_BYTES = 4 * 1024 * 1024
"""Largest JSON document read (bytes); calibrations and tunings are a few kB."""
MAX_TABLE_BYTES = 64 * 1024 * 1024
"""Largest table (CSV) read (bytes)."""
MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays/objects accepted in a JSON document."""
MAX_JSON_INT_DIGITS = 400
"""Longest whole number a JSON document may hold, characters (a float ends at 309 digits; those up to here are
refused by the field that reads them, naming it)."""

# Plausible magnitudes of a step (SI): prismatic joint 3 in metres, rotary joints in radians.
# A MM3A prismatic step is about 1 um (the paper: a = 972 nm), a rotary one tens of urad.
STEP_RANGE = {"m": (1e-10, 1e-4), "rad": (1e-10, 1e-2)}
"""``unit -> (smallest, largest)`` magnitude accepted for a step size or a step-size term."""


FILE_URL_DATABASE = (
    "a file: URL is not read (it would be a file named 'file:...', on Windows a hidden stream): "
    "give the database file's path"
)
"""Why ``--db file:lab.db`` (SQLite's URI form; RFC 8089's ``file:/data/lab.db``) is refused, wherever one is named."""


def is_file_url(text: str) -> bool:
    """Whether ``text`` is a ``file:`` URL (any case; ``file://`` too), not a path."""
    return text.strip()[:5].lower() == "file:"


def special_kind(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is (``"a folder"``, ``"a FIFO ..."``), or ``None`` for a regular file."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (a named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def regular_file(path: str | os.PathLike[str], what: str) -> Path:
    """``path`` if it is a regular file (a symbolic link to one counts); else ``ValueError`` naming it and what it is.

    Checked with ``stat`` before anything opens it: a folder, a FIFO (whose opening
    blocks until someone writes), a device (``/dev/zero`` never ends) or a socket is
    refused, never opened. ``what`` names the kind of file in the message.
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise ValueError(f"cannot read {what} {p}: no such {what} file") from None
    except OSError as e:
        raise ValueError(f"{p}: cannot read the {what} file ({e.strerror or e})") from None
    kind = special_kind(st.st_mode)
    if kind == "a folder":
        raise ValueError(f"{p}: is a folder, not a {what} file")
    if kind is not None:
        raise ValueError(f"{p}: is {kind}, not a regular file; give a {what} file")
    return p


def writable_target(path: str | os.PathLike[str], what: str = "output") -> Path:
    """The file a write to ``path`` should replace: ``path``, or the file a symbolic link at it points to.

    Raises ``ValueError`` naming ``path`` when what is there is not a regular file (a
    folder, a FIFO, a device such as ``/dev/full`` or ``/dev/null``, a socket): such a
    thing is never opened, written through or replaced by a file. A path where nothing
    is yet is fine.
    """
    p = Path(path)
    target = Path(os.path.realpath(p)) if p.is_symlink() else p
    try:
        st = os.stat(target)
    except FileNotFoundError:
        return target
    except OSError as e:
        raise ValueError(f"{p}: cannot write the {what} file ({e.strerror or e})") from None
    kind = special_kind(st.st_mode)
    if kind is not None:
        raise ValueError(f"{p}: is {kind}, not a file; give the path of a file to write the {what} to")
    return target


def read_text_bounded(path: str | os.PathLike[str], what: str, max_bytes: int = MAX_JSON_BYTES) -> str:
    """The text of a regular file of at most ``max_bytes`` bytes (UTF-8).

    Raises ``ValueError`` ``"<path>: <reason>"`` for a missing file, a folder, a FIFO or
    device (never opened, so a pipe cannot hang the reader: :func:`regular_file`), a file
    over the limit, or text that is not UTF-8. ``what`` names the kind of file in the message.
    """
    p = regular_file(path, what)
    try:
        with open(p, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as e:
        raise ValueError(f"{p}: cannot read the {what} file ({e.strerror or e})") from None
    if len(data) > max_bytes:
        raise ValueError(f"{p}: larger than the {max_bytes // 1024} KiB limit for a {what} file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ValueError(_not_utf8(p, what, data, f"byte {e.start}")) from None


_UTF16 = (b"\xff\xfe", b"\xfe\xff")  # UTF-16 byte-order marks: Windows Notepad's "Unicode"


def _not_utf8(p: Path, what: str, data: bytes, where: str) -> str:
    """Why a file that is not UTF-8 is refused, and how to save it (``data``: its start; ``where``: the bad byte)."""
    if data[:2] in _UTF16:
        return f"{p}: UTF-16 text, not UTF-8: save it as UTF-8 (in Notepad: Save as, Encoding UTF-8)"
    if what == "CSV" or "table" in what:  # Excel's plain "CSV" writes Windows-1252 (a unit's µ is byte 0xb5)
        return f"{p}: not UTF-8 text ({where}): save it as UTF-8 (a spreadsheet's 'CSV UTF-8'; its plain 'CSV' is " \
               "Windows-1252)"
    return f"{p}: not UTF-8 text ({where})"


def text_lines(path: str | os.PathLike[str], what: str) -> Iterator[str]:
    """The lines of a regular UTF-8 text file, read a block at a time (memory bounded by a line).

    The same refusals as :func:`read_text_bounded` (:func:`regular_file`), raised here, before any
    line is read (a missing file, a folder, a FIFO or device, which is never opened), but no size limit: the
    caller streams. A line that is not UTF-8 raises ``ValueError`` naming its number when it
    is reached; a leading byte-order mark is dropped. Lines keep their line endings.
    """
    p = regular_file(path, what)
    try:
        f = open(p, "rb")  # closed by the generator
    except OSError as e:
        raise ValueError(f"{p}: cannot read the {what} file ({e.strerror or e})") from None
    return _decoded(f, p, what)


def _decoded(f: io.BufferedReader, p: Path, what: str) -> Iterator[str]:
    with f:
        for n, raw in enumerate(f, start=1):
            try:
                line = raw.decode("utf-8-sig" if n == 1 else "utf-8")
            except UnicodeDecodeError as e:
                where = f"line {n}, byte {e.start + 1} of the line"
                raise ValueError(_not_utf8(p, what, raw if n == 1 else b"", where)) from None
            yield line


_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)


def check_json_text(text: str, where: str, max_depth: int = MAX_JSON_DEPTH) -> str:
    """Refuse JSON text nested deeper than ``max_depth`` or using ``NaN``/``Infinity``.

    Runs before ``json.loads`` so deep nesting cannot raise ``RecursionError``. Returns
    ``text``; raises ``ValueError`` ``"<where>: <reason>"``.

    >>> check_json_text('{"a": [1, 2]}', "x")
    '{"a": [1, 2]}'
    >>> check_json_text('[' * 40 + ']' * 40, "x")
    Traceback (most recent call last):
    ...
    ValueError: x: JSON nested deeper than 32 levels
    """
    bare = _STRING.sub('""', text)
    if re.search(r"\b(NaN|Infinity)\b", bare):
        raise ValueError(f"{where}: NaN/Infinity are not numbers a file may hold (use finite values)")
    depth = 0
    for ch in re.findall(r"[\[\]{}]", bare):
        depth += 1 if ch in "[{" else -1
        if depth > max_depth:
            raise ValueError(f"{where}: JSON nested deeper than {max_depth} levels")
    return text


def read_json_text(path: str | os.PathLike[str], what: str, max_bytes: int = MAX_JSON_BYTES) -> str:
    """:func:`read_text_bounded` + :func:`check_json_text`: text safe to give ``json.loads``."""
    return check_json_text(read_text_bounded(path, what, max_bytes), str(path))


# what json's parser says, as a person would (its own words name its grammar, not the file)
_JSON_PROBLEMS = (
    ("Expecting property name", "a key must be a string in double quotes (no trailing comma before '}')"),
    ("Expecting value", "a value is missing or is not JSON (text in double quotes, no trailing comma)"),
    ("Expecting ',' delimiter", "a ',' is missing between two items"),
    ("Expecting ':' delimiter", "a ':' is missing after a key"),
    ("Extra data", "more text after the end of the document"),
    ("Unterminated string", "a string is not closed with a double quote"),
    ("Invalid control character", "a control character (a tab, a line break) inside a string"),
    ("Invalid \\escape", "a backslash escape JSON does not know inside a string"),
)


class _LongNumber(ValueError):
    """A JSON integer of more than :data:`MAX_JSON_INT_DIGITS` digits (its length in ``args[0]``)."""


def _json_int(text: str) -> int:
    """``int(text)`` for ``json.loads``, refusing what no field takes before Python's 4300-digit limit speaks."""
    if len(text) > MAX_JSON_INT_DIGITS:
        raise _LongNumber(len(text))
    return int(text)


def _once(twice: Callable[[str], Exception]) -> Callable[[list[tuple[str, Any]]], dict[str, Any]]:
    """An ``object_pairs_hook`` that raises ``twice(key)`` for a key given twice in one object."""

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in items:
            if k in out:
                raise twice(k)
            out[k] = v
        return out

    return pairs


def _no_key_twice(where: str) -> Callable[[list[tuple[str, Any]]], dict[str, Any]]:
    return _once(lambda k: ValueError(f"{where}: the key {k!r} is given twice in one object (which one is meant?)"))


def natural_order(text: str) -> tuple[tuple[int, int | str], ...]:
    """A sort key putting names and labels in the order people number them: runs of digits compare as numbers.

    ``day9`` before ``day10``, ``f2.png`` before ``f10.png``; an ISO date sorts as its date and
    ``2026-11-22 am`` before ``2026-11-22 pm``. Names equal as numbers (``f01``, ``f1``) tie: a
    caller that needs a total order adds the text itself (:func:`stickslip.vision.files.name_order`).
    """
    return tuple((0, int(part)) if part.isdigit() else (1, part) for part in _DIGIT_RUNS.split(text) if part)


_DIGIT_RUNS = re.compile(r"(\d+)")


class _KeyTwice(Exception):
    pass


def repeated_key(text: str | bytes) -> str | None:
    """The first key given twice in one object of the JSON document ``text``, else ``None`` (also for text that is
    not JSON, or nested too deeply to read: the reader that follows says why). Python's ``json`` keeps the last
    of two silently; a request's body or message naming ``"joint"`` twice would move the joint named last."""
    try:
        json.loads(text, object_pairs_hook=_once(_KeyTwice))
    except _KeyTwice as e:
        return str(e.args[0])
    except (ValueError, RecursionError, TypeError):
        return None
    return None


def loads_json(text: str, where: str, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """The JSON document in ``text``, read strictly; ``ValueError`` ``"<where>: <reason>"`` otherwise.

    The one JSON reader of the toolkit (calibrations, tunings, device state, stored
    documents): nesting deeper than ``max_depth`` and ``NaN``/``Infinity`` are refused
    (:func:`check_json_text`), so is a key given twice in one object (``json`` would keep
    the last silently), and a syntax error is said in words with its line and column.

    >>> loads_json('{"a": 1}', "x.json")
    {'a': 1}
    >>> loads_json('{"version": 1, "version": 9}', "x.json")
    Traceback (most recent call last):
    ...
    ValueError: x.json: the key 'version' is given twice in one object (which one is meant?)
    >>> loads_json('[1 2]', "x.json")
    Traceback (most recent call last):
    ...
    ValueError: x.json: not valid JSON at line 1, column 4: a ',' is missing between two items
    """
    check_json_text(text, where, max_depth)
    try:
        return json.loads(text, object_pairs_hook=_no_key_twice(where), parse_int=_json_int)
    except _LongNumber as e:
        raise ValueError(f"{where}: a whole number of {e.args[0]} characters: no field takes one so long") from None
    except json.JSONDecodeError as e:
        reason = next((ours for theirs, ours in _JSON_PROBLEMS if e.msg.startswith(theirs)), "a syntax error")
        raise ValueError(f"{where}: not valid JSON at line {e.lineno}, column {e.colno}: {reason}") from None
    except RecursionError:  # pragma: no cover - check_json_text bounds the depth first
        raise ValueError(f"{where}: JSON nested too deeply") from None


def dumps_json(value: Any, where: str, indent: int | None = None) -> str:
    """``value`` as JSON text :func:`loads_json` reads back; ``ValueError`` naming the first NaN or infinity.

    ``json.dumps`` writes ``NaN`` and ``Infinity``, which no reader of the toolkit takes:
    a file or stored document holding one is refused when read, so it is refused here,
    before anything is written (the old file, or the stored value, is kept).

    >>> dumps_json({"a": [1.0, float("nan")]}, "x.json")
    Traceback (most recent call last):
    ...
    ValueError: x.json: a.1 is nan: NaN/Infinity are not numbers a file may hold; nothing written
    """
    try:
        return json.dumps(value, indent=indent, allow_nan=False)
    except ValueError:
        at = _non_finite(value, "") or "a value"
        raise ValueError(f"{where}: {at}: NaN/Infinity are not numbers a file may hold; nothing written") from None


def _non_finite(value: Any, at: str) -> str:
    """Where in ``value`` its first NaN or infinity is (``"a.1 is nan"``)."""
    items: Iterable[tuple[object, Any]] = ()
    if isinstance(value, float) and not math.isfinite(value):
        return f"{at or 'the value'} is {value!r}"
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, (list, tuple)):
        items = enumerate(value)
    for k, v in items:
        found = _non_finite(v, f"{at}.{k}" if at else str(k))
        if found:
            return found
    return ""


def read_json(path: str | os.PathLike[str], what: str, max_bytes: int = MAX_JSON_BYTES) -> Any:
    """The JSON document in the file ``path`` (:func:`read_text_bounded` + :func:`loads_json`)."""
    return loads_json(read_text_bounded(path, what, max_bytes), str(path))


def check_version(data: object, where: str, what: str, newest: int) -> None:
    """Refuse a document whose ``"version"`` is newer than ``newest`` (this release reads up to it), naming it.

    A document without a version, or with one this release knows, passes; the caller
    checks what else its versions mean.
    """
    if not isinstance(data, dict) or "version" not in data:
        return
    v = data["version"]
    if isinstance(v, int) and not isinstance(v, bool) and v > newest:
        raise ValueError(
            f"{where}: {what} version {v} is newer than this stickslip reads ({newest}): upgrade stickslip"
        )


# -- calibration documents ---------------------------------------------------------------------

_PRISMATIC = {"a": "step", "c": "term", "b": "ratio"}
_ROTARY = {"gamma0": "step", "d": "term"}


def json_kind(value: object) -> str:
    """What a JSON value is, in JSON's words (a message's "got ..."; Python's ``NoneType`` or ``dict`` tell nobody).

    >>> json_kind(None), json_kind([1]), json_kind("x"), json_kind(True), json_kind(3), json_kind({})
    ('null', 'a list', 'a text', 'true or false', 'a number', 'an object')
    """
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a text"
    if isinstance(value, (list, tuple)):
        return "a list"
    return "an object" if isinstance(value, dict) else type(value).__name__


def finite_number(value: object, where: str) -> float:
    """A JSON number as a float, or ``ValueError`` naming ``where``: a string, a boolean, null, NaN or infinity."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    try:
        x = float(value)
    except OverflowError:  # an integer of 309 digits or more: JSON has no limit, a float has
        x = math.inf
    if not math.isfinite(x):
        shown = "an integer beyond ±1.8e308" if isinstance(value, int) else repr(value)
        raise ValueError(f"{where} must be a finite number, got {shown}")
    return x


def check_unit(given: object, expected: str | None, where: str) -> None:
    """Refuse a stored value whose ``unit`` is not the one stickslip writes (its value would be read in SI anyway).

    A missing unit (a hand-written file) is taken as SI. ``ValueError`` names ``where`` and both units.
    """
    if given is not None and expected is not None and given != expected:
        raise ValueError(f"{where}: unit {given!r:.40}, but the value is read in {expected!r} (values are SI: "
                         f"convert it and write {expected!r})")


_STEP_DISPLAY = {"m": (("nm", 1e-9), ("µm", 1e-6)), "rad": (("µrad", 1e-6), ("mrad", 1e-3))}


def step_unit_slip(v: float, unit: str) -> str | None:
    """``"in nm? 970 nm is 9.7e-07 m"``: the readings of a step size ``v`` beyond :data:`STEP_RANGE` of ``unit``
    (``"m"`` or ``"rad"``) in the units people read steps in (nm and µm, µrad and mrad) that are step sizes."""
    lo, hi = STEP_RANGE[unit]
    if not math.isfinite(v) or abs(v) <= hi:
        return None
    fits = [(u, v * f) for u, f in _STEP_DISPLAY[unit] if lo <= abs(v * f) <= hi]
    if not fits:
        return None
    said = ", ".join(f"{v:.6g} {u} is {x:.6g} {unit}" for u, x in fits)
    return f"in {' or '.join(u for u, _ in fits)}? {said}"


def _check_scale(v: float, unit: str, where: str, signed: bool) -> None:
    lo, hi = STEP_RANGE[unit]
    size = abs(v) if signed else v
    if not signed and v <= 0:
        raise ValueError(f"{where} must be a positive step size in {unit}, got {v!r}")
    if size > hi or (not signed and size < lo):
        hint = " (nm or urad written where SI metres/radians are expected?)" if size > hi else ""
        raise ValueError(f"{where} = {v!r} {unit} is outside the plausible range {lo:g}..{hi:g} {unit}{hint}")


def _record_joint(rec: object, where: str) -> tuple[dict[str, Any], int]:
    """The record (an object) and its joint (1, 2 or 3), or ``ValueError`` naming ``where``."""
    if not isinstance(rec, dict):
        raise ValueError(f"{where} must be an object, got {json_kind(rec)}")
    joint = rec.get("joint")
    if joint not in (1, 2, 3) or isinstance(joint, bool):
        raise ValueError(f"{where}.joint must be 1, 2 or 3, got {joint!r}")
    direction = rec.get("direction")
    if not isinstance(direction, str) or direction not in ("+", "-"):
        raise ValueError(f'{where}.direction must be "+" or "-", got {direction!r}')
    return rec, int(joint)


def _check_parameter(rec_: object, i: int) -> None:
    where = f"parameters[{i}]"
    rec, joint = _record_joint(rec_, where)
    name = rec.get("name")
    kinds = _PRISMATIC if joint_spec(joint).prismatic else _ROTARY
    if not isinstance(name, str) or name not in kinds:
        raise ValueError(f"{where}.name must be one of {sorted(kinds)} for joint {joint}, got {name!r}")
    where = f"{where} (joint {joint} {name})"
    v = finite_number(rec.get("value"), where)
    if kinds[name] == "ratio":
        if not 0.0 <= v < 1.0:
            raise ValueError(f"{where} must satisfy 0 <= b < 1 (eta = 1 - b|cos q2| > 0), got {v!r}")
    else:
        _check_scale(v, joint_spec(joint).unit, where, signed=kinds[name] == "term")
    if rec.get("stderr") is not None:
        se = finite_number(rec.get("stderr"), f"{where} stderr")
        if se < 0:
            raise ValueError(f"{where} stderr must be >= 0, got {se!r}")
    if joint_spec(joint).rotary:
        q3 = finite_number(rec.get("q3"), f"{where} q3")
        if not -1e-3 <= q3 <= 0.1:
            raise ValueError(f"{where} q3 = {q3!r} m is outside 0..0.1 m")


def _check_once(rec: dict[str, Any], i: int, seen: dict[tuple[object, ...], int]) -> None:
    """Refuse a parameter given twice (the same joint, direction, name and q3): the model would take one silently."""
    joint = rec["joint"]
    q3 = float(rec["q3"]) if joint_spec(joint).rotary else None
    key = (joint, rec["direction"], rec["name"], q3)
    if key in seen:
        at = "" if q3 is None else f" at q3 = {q3:g} m"
        raise ValueError(
            f"parameters[{i}] gives joint {joint}{rec['direction']} {rec['name']}{at} again "
            f"(parameters[{seen[key]}] gives it too): keep one"
        )
    seen[key] = i


def check_calibration_dict(data: object) -> None:
    """Check a calibration document's structure and physical ranges before it is used.

    Checks: an object; ``parameters`` and ``constant_steps`` lists of objects; every value
    finite; ``0 <= b < 1``; step sizes positive and within :data:`STEP_RANGE` for the joint's
    unit (metres for joint 3, radians for joints 1 and 2; a constant step's own ``unit``, ``m``
    or ``rad``, where it gives one: a stage's); ``provenance`` an object.
    Raises ``ValueError`` naming the field and the reason. The format/version check is the
    caller's (``Calibration.from_dict``).
    """
    if not isinstance(data, dict):
        raise ValueError(f"a calibration must be a JSON object, got {json_kind(data)}")
    for key in ("parameters", "constant_steps"):
        if key in data and not isinstance(data[key], list):
            raise ValueError(f"{key} must be a list, got {json_kind(data[key])}")
    if data.get("provenance") is not None and not isinstance(data["provenance"], dict):
        raise ValueError(f"provenance must be an object, got {json_kind(data['provenance'])}")
    prov = data.get("provenance") or {}
    for key in ("rows", "rows_used"):
        n = prov.get(key)
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= 10**9):
            raise ValueError(f"provenance.{key} must be a count of rows (0..1e9), got {n!r}")
    if (
        isinstance(prov.get("rows"), int)
        and isinstance(prov.get("rows_used"), int)
        and prov["rows_used"] > prov["rows"]
    ):
        raise ValueError(f"provenance.rows_used ({prov['rows_used']}) is more than provenance.rows ({prov['rows']})")
    for key in ("day", "method", "created"):
        if data.get(key) is not None and not isinstance(data[key], str):
            raise ValueError(f"{key} must be a string, got {data[key]!r}")
    seen: dict[tuple[object, ...], int] = {}
    for i, rec in enumerate(data.get("parameters") or []):
        _check_parameter(rec, i)
        _check_once(rec, i, seen)
    steps: dict[tuple[int, str], int] = {}
    for i, rec in enumerate(data.get("constant_steps") or []):
        where = f"constant_steps[{i}]"
        step, joint = _record_joint(rec, where)
        if (k := steps.setdefault((joint, step["direction"]), i)) != i:
            raise ValueError(
                f"{where} gives joint {joint}{step['direction']}'s constant step again "
                f"(constant_steps[{k}] gives it too): keep one"
            )
        v = finite_number(step.get("value"), f"{where} (joint {joint})")
        unit = step.get("unit")  # a stage's joints 1 and 2 are prismatic: their steps in m (the file says)
        if unit not in ("m", "rad"):
            unit = joint_spec(joint).unit  # a file without it, or a unit Calibration.from_dict refuses by name
        _check_scale(v, unit, f"{where} (joint {joint})", signed=False)


# -- tuning documents ----------------------------------------------------------------------------


def check_tuning_dict(data: object) -> None:
    """Check a stop-detector tuning's numbers: finite, counts positive and bounded, band inside Nyquist.

    Raises ``ValueError`` naming the field. Structure (names, kinds) is the caller's.
    """
    if not isinstance(data, dict):
        raise ValueError(f"a tuning must be a JSON object, got {json_kind(data)}")
    rate = data.get("sample_rate", 48000)
    for k in ("sample_rate", "frame", "hop", "max_dips"):
        if k in data:
            v = data[k]
            bad = isinstance(v, bool) or not isinstance(v, (int, float))
            if bad or (isinstance(v, float) and not math.isfinite(v)):  # math.isfinite(10**400): OverflowError
                raise ValueError(f"{k} must be a whole number, got {v!r}")
            if not 0 < v <= 10_000_000 and not (k == "max_dips" and v == 0):
                shown = repr(v) if abs(v) < 1e30 else "a number beyond 1e30"
                raise ValueError(f"{k} must be in 1..10000000, got {shown}")
    for k in ("threshold_db", "hold_s", "hysteresis_db", "release_s", "onset_lag_s", "latency_s"):
        if data.get(k) is not None:
            finite_number(data[k], k)
    for k in ("band_hz", "reference_hz"):
        band = data.get(k)
        if band is None:
            continue
        if not (isinstance(band, list) and len(band) == 2):
            raise ValueError(f"{k} must be [low_Hz, high_Hz], got {band!r}")
        lo, hi = (finite_number(x, k) for x in band)
        nyquist = float(rate) / 2 if isinstance(rate, (int, float)) and not isinstance(rate, bool) else math.inf
        if not 0 <= lo < hi <= nyquist:
            raise ValueError(f"{k} must satisfy 0 <= low < high <= {nyquist:g} Hz (Nyquist), got {band!r}")


def read_tuning_text(path: str | os.PathLike[str], error: type[ValueError] = ValueError) -> str:
    """The text of a tuning file, bounded, read strictly (:func:`loads_json`) and range-checked.

    Problems (not JSON, a key given twice, a range) raise ``error`` (a ``ValueError``
    subclass the caller already handles), naming the file.
    """
    try:
        text = read_json_text(path, "tuning")
        data = loads_json(text, str(path))
        try:
            check_tuning_dict(data)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
    except ValueError as e:
        raise error(str(e)) from None
    return text


# -- spreadsheet cells ---------------------------------------------------------------------------

FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
"""What a spreadsheet reads as the start of a formula in a CSV cell (OWASP's CSV injection list)."""
_PLAIN_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\Z")


def needs_guard(cell: str) -> bool:
    """Whether :func:`guard_cell` changes ``cell`` (it would start a formula, after any leading quotes)."""
    rest = cell.lstrip("'")
    if not rest.startswith(FORMULA_START) or rest in ("+", "-"):
        return False
    return _PLAIN_NUMBER.match(rest) is None


def guard_cell(cell: str) -> str:
    """A CSV cell as it is written: one a spreadsheet would run as a formula gets a leading ``'``.

    The rule (OWASP's, for CSV injection), kept exact so that numbers stay numbers:

    * a cell that begins with ``=``, ``+``, ``-``, ``@``, a tab or a carriage return is
      prefixed with ``'`` (a spreadsheet then shows it as text);
    * except a plain decimal number (``-1.5707963``, ``+3``, ``-2.5e-06``: what the
      tables hold in SI units, and what a spreadsheet reads as a number, never a
      formula) and a lone ``+`` or ``-`` (the direction column: nothing to compute);
    * a cell that begins with quotes before such a start gets one more quote, so that
      :func:`unguard_cell` gives every cell back exactly: guarding is reversible.

    >>> [guard_cell(c) for c in ("=HYPERLINK(x)", "-1.5e-06", "+", "@SUM(A1)", "'=x", "day1", "-1+1")]
    ["'=HYPERLINK(x)", '-1.5e-06', '+', "'@SUM(A1)", "''=x", 'day1', "'-1+1"]
    """
    return "'" + cell if needs_guard(cell) else cell


def unguard_cell(cell: str) -> str:
    """A cell as :func:`guard_cell` was given it (our own readers take the guard off).

    >>> [unguard_cell(c) for c in ("'=HYPERLINK(x)", "''=x", "'abc", "-1.5")]
    ['=HYPERLINK(x)', "'=x", "'abc", '-1.5']
    """
    return cell[1:] if cell.startswith("'") and needs_guard(cell[1:]) else cell


# -- safe writes -------------------------------------------------------------------------------


def _file_mode(p: Path) -> int:
    """The permission bits a write to ``p`` should leave: the file's own if it is there, else 0666 less the umask."""
    try:
        return stat.S_IMODE(p.stat().st_mode)
    except OSError:
        mask = os.umask(0)  # reading the umask means setting it: put it straight back
        os.umask(mask)
        return 0o666 & ~mask


class WriteError(OSError):
    """A file could not be written; the message names it, says why, and that the old file is kept.

    An ``OSError`` (with the errno, reason and the path asked for), whose text is one
    line for a person: ``cannot write out.csv: No space left on device; the old file is
    kept as it was`` (or ``; nothing was written`` where there was none).
    """

    def __init__(self, path: Path, error: OSError, kept: bool) -> None:
        super().__init__(error.errno, error.strerror or str(error), str(path))
        reason = error.strerror or str(error)
        after = "the old file is kept as it was" if kept else "nothing was written"
        self.message = f"cannot write {path}: {reason}; {after}"

    def __str__(self) -> str:
        return self.message


def atomic_write(path: str | os.PathLike[str], write: Callable[[Any], None], mode: str = "w") -> Path:
    """Write ``path`` through a temporary file in its folder, then ``os.replace`` it.

    The checked write every output file of the toolkit goes through:

    * what is at ``path`` must be a regular file or nothing (:func:`writable_target`): a
      folder, a FIFO or a device (``/dev/full``) is refused, never replaced by a file; a
      symbolic link is written through (the file it points to is replaced, the link stays);
    * ``write(f)`` receives the open temporary file; it is flushed and ``fsync``-ed before
      the rename, and the folder is ``fsync``-ed after it (POSIX), so the new file is on
      the disk when this returns;
    * if anything fails (a full disk, a quota, an I/O error, a read-only folder, an
      exception in ``write``) the temporary file is removed and the old ``path`` is left
      exactly as it was; an ``OSError`` is raised as :class:`WriteError` (one line naming
      the file, the reason and that the old file is kept), the writer's own exception as it is;
    * a file that is read-only for this user (``chmod a-w``, the Windows read-only flag) is
      refused as a plain write refuses it: a rename into its folder would replace it on POSIX;
    * inside :func:`atomic_group` the rename waits for the group's end, with every other file's.

    The file gets the permissions a plain ``open(path, "w")`` would give it (an existing
    file keeps its own; a new one 0666 less the umask), not the temporary file's 0600:
    colleagues who read a lab's shared results folder still can.
    """
    asked = Path(path)
    p, tmp = _staged(asked, write, mode)
    group = _GROUP.get()
    if group is not None:
        group.append((asked, p, tmp))
        return p
    _rename(asked, p, tmp)
    return p


def _staged(asked: Path, write: Callable[[Any], None], mode: str) -> tuple[Path, str]:
    """The file to replace, and the temporary file beside it holding what ``write`` wrote (flushed, synced)."""
    p = writable_target(asked)
    folder = p.parent if str(p.parent) else Path(".")
    mode_bits = _file_mode(p)
    kept = p.exists()
    if kept and not os.access(p, os.W_OK):  # a rename would replace it (POSIX): refused, as a plain write is
        raise WriteError(asked, PermissionError(errno.EACCES, "the file is read-only"), kept)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{temp_stem(p.name)}.", suffix=".tmp", dir=folder)
    except OSError as e:  # the folder is not there, or not writable: say so of the file asked for
        raise WriteError(asked, e, kept) from None
    try:
        kwargs: dict[str, Any] = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, mode, **kwargs) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode_bits)  # mkstemp made it private (0600): the permissions a plain write would give
    except BaseException as e:
        _unlink(tmp)
        if isinstance(e, OSError) and not isinstance(e, WriteError):
            raise WriteError(asked, e, kept) from None
        raise
    return p, tmp


TEMP_STEM_BYTES = 200
"""Longest part of a file's name its temporary file's name repeats, bytes of UTF-8: the temporary adds up to 40
(``.NAME.xxxxxxxx.tmp``; a backup's ``.NAME.PID-xxxxxxxx.part`` and SQLite's ``-journal`` beside it), and a file
system's name limit is 255 (bytes on Linux and macOS, UTF-16 units on Windows)."""


def temp_stem(name: str) -> str:
    """``name``, cut to :data:`TEMP_STEM_BYTES` bytes at a character's end: what a temporary file beside it repeats.

    A legal name of 242 to 255 bytes made its temporary file's name too long, and the write
    failed ("File name too long") for a file a plain write could make.
    """
    return name.encode("utf-8")[:TEMP_STEM_BYTES].decode("utf-8", errors="ignore")


def _rename(asked: Path, p: Path, tmp: str) -> None:
    kept = p.exists()
    try:
        os.replace(tmp, p)
    except BaseException as e:
        _unlink(tmp)
        if isinstance(e, OSError):
            raise WriteError(asked, e, kept) from None
        raise
    _sync_folder(p.parent if str(p.parent) else Path("."))


def _unlink(tmp: str) -> None:
    try:
        os.unlink(tmp)
    except OSError:
        pass


_GROUP: contextvars.ContextVar[list[tuple[Path, Path, str]] | None] = contextvars.ContextVar("_GROUP", default=None)


@contextmanager
def atomic_group() -> Iterator[None]:
    """Files written together or not at all: every :func:`atomic_write` inside is renamed into place at the end.

    Each file is written whole to its temporary file first; a write that fails (a disk that
    fills half-way through a report) removes every temporary file of the group, and every
    old file stays as it was: never a folder of new figures beside an old page. Only the
    renames, which need no space, remain once all are written. A file written in the group
    reads as its old self until the group ends.
    """
    staged: list[tuple[Path, Path, str]] = []
    token = _GROUP.set(staged)
    try:
        yield
    except BaseException:
        for _, _, tmp in staged:
            _unlink(tmp)
        raise
    finally:
        _GROUP.reset(token)
    for i, (asked, p, tmp) in enumerate(staged):
        try:
            _rename(asked, p, tmp)
        except BaseException:
            for _, _, left in staged[i + 1 :]:
                _unlink(left)
            raise


def _sync_folder(folder: Path) -> None:
    """``fsync`` a folder after a rename in it, so the new name survives a power cut (POSIX; elsewhere nothing)."""
    if os.name != "posix":
        return
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot sync a folder; the file itself is synced
    finally:
        os.close(fd)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """:func:`atomic_write` of a string (UTF-8)."""
    return atomic_write(path, lambda f: f.write(text))
