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

:func:`atomic_write_text` writes an output file through a temporary file in the same
folder and ``os.replace``: a failed write leaves the old file as it was.

This module imports only the standard library (it sits below every other layer).
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import stat
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from .joints import joint_spec

MAX_JSON_BYTES = 4 * 1024 * 1024
"""Largest JSON document read (bytes); calibrations and tunings are a few kB."""
MAX_TABLE_BYTES = 64 * 1024 * 1024
"""Largest table (CSV) read (bytes)."""
MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays/objects accepted in a JSON document."""

# Plausible magnitudes of a step (SI): prismatic joint 3 in metres, rotary joints in radians.
# A MM3A prismatic step is about 1 um (the paper: a = 972 nm), a rotary one tens of urad.
STEP_RANGE = {"m": (1e-10, 1e-4), "rad": (1e-10, 1e-2)}
"""``unit -> (smallest, largest)`` magnitude accepted for a step size or a step-size term."""


def read_text_bounded(path: str | os.PathLike[str], what: str, max_bytes: int = MAX_JSON_BYTES) -> str:
    """The text of a regular file of at most ``max_bytes`` bytes (UTF-8).

    Raises ``ValueError`` ``"<path>: <reason>"`` for a missing file, a folder, a FIFO or
    device (never opened, so a pipe cannot hang the reader), a file over the limit, or
    text that is not UTF-8. ``what`` names the kind of file in the message.
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise ValueError(f"cannot read {what} {p}: no such {what} file") from None
    except OSError as e:
        raise ValueError(f"{p}: cannot read the {what} file ({e.strerror or e})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{p}: is a folder, not a {what} file")
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{p}: not a regular file (a pipe or device?); give a {what} file")
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
        raise ValueError(f"{p}: not UTF-8 text (byte {e.start})") from None


def text_lines(path: str | os.PathLike[str], what: str) -> Iterator[str]:
    """The lines of a regular UTF-8 text file, read a block at a time (memory bounded by a line).

    The same refusals as :func:`read_text_bounded`, raised here, before any line is read (a
    missing file, a folder, a FIFO or device, which is never opened), but no size limit: the
    caller streams. A line that is not UTF-8 raises ``ValueError`` naming its number when it
    is reached; a leading byte-order mark is dropped. Lines keep their line endings.
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise ValueError(f"cannot read {what} {p}: no such {what} file") from None
    except OSError as e:
        raise ValueError(f"{p}: cannot read the {what} file ({e.strerror or e})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{p}: is a folder, not a {what} file")
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{p}: not a regular file (a pipe or device?); give a {what} file")
    try:
        f = open(p, "rb")  # closed by the generator
    except OSError as e:
        raise ValueError(f"{p}: cannot read the {what} file ({e.strerror or e})") from None
    return _decoded(f, p)


def _decoded(f: io.BufferedReader, p: Path) -> Iterator[str]:
    with f:
        for n, raw in enumerate(f, start=1):
            try:
                line = raw.decode("utf-8-sig" if n == 1 else "utf-8")
            except UnicodeDecodeError as e:
                raise ValueError(f"{p}: not UTF-8 text (line {n}, byte {e.start + 1} of the line)") from None
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


# -- calibration documents ---------------------------------------------------------------------

_PRISMATIC = {"a": "step", "c": "term", "b": "ratio"}
_ROTARY = {"gamma0": "step", "d": "term"}


def finite_number(value: object, where: str) -> float:
    """A JSON number as a float, or ``ValueError`` naming ``where``: a string, a boolean, null, NaN or infinity."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    return float(value)


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
        raise ValueError(f"{where} must be an object, got {type(rec).__name__}")
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


def check_calibration_dict(data: object) -> None:
    """Check a calibration document's structure and physical ranges before it is used.

    Checks: an object; ``parameters`` and ``constant_steps`` lists of objects; every value
    finite; ``0 <= b < 1``; step sizes positive and within :data:`STEP_RANGE` for the joint's
    unit (metres for joint 3, radians for joints 1 and 2); ``provenance`` an object.
    Raises ``ValueError`` naming the field and the reason. The format/version check is the
    caller's (``Calibration.from_dict``).
    """
    if not isinstance(data, dict):
        raise ValueError(f"a calibration must be a JSON object, got {type(data).__name__}")
    for key in ("parameters", "constant_steps"):
        if key in data and not isinstance(data[key], list):
            raise ValueError(f"{key} must be a list, got {type(data[key]).__name__}")
    if data.get("provenance") is not None and not isinstance(data["provenance"], dict):
        raise ValueError(f"provenance must be an object, got {type(data['provenance']).__name__}")
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
    for i, rec in enumerate(data.get("parameters") or []):
        _check_parameter(rec, i)
    for i, rec in enumerate(data.get("constant_steps") or []):
        where = f"constant_steps[{i}]"
        step, joint = _record_joint(rec, where)
        v = finite_number(step.get("value"), f"{where} (joint {joint})")
        _check_scale(v, joint_spec(joint).unit, f"{where} (joint {joint})", signed=False)


# -- tuning documents ----------------------------------------------------------------------------


def check_tuning_dict(data: object) -> None:
    """Check a stop-detector tuning's numbers: finite, counts positive and bounded, band inside Nyquist.

    Raises ``ValueError`` naming the field. Structure (names, kinds) is the caller's.
    """
    if not isinstance(data, dict):
        raise ValueError(f"a tuning must be a JSON object, got {type(data).__name__}")
    rate = data.get("sample_rate", 48000)
    for k in ("sample_rate", "frame", "hop", "max_dips"):
        if k in data:
            v = data[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{k} must be a whole number, got {v!r}")
            if not 0 < v <= 10_000_000 and not (k == "max_dips" and v == 0):
                raise ValueError(f"{k} must be in 1..10000000, got {v!r}")
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
    """The text of a tuning file, bounded, depth-checked and, if it parses, range-checked.

    Text that is not JSON is returned as is, for the caller's parser to report. Problems
    raise ``error`` (a ``ValueError`` subclass the caller already handles).
    """
    try:
        text = read_json_text(path, "tuning")
        try:
            data = json.loads(text)
        except ValueError:
            return text
        try:
            check_tuning_dict(data)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
    except ValueError as e:
        raise error(str(e)) from None
    return text


# -- safe writes -------------------------------------------------------------------------------


def _file_mode(p: Path) -> int:
    """The permission bits a write to ``p`` should leave: the file's own if it is there, else 0666 less the umask."""
    try:
        return stat.S_IMODE(p.stat().st_mode)
    except OSError:
        mask = os.umask(0)  # reading the umask means setting it: put it straight back
        os.umask(mask)
        return 0o666 & ~mask


def atomic_write(path: str | os.PathLike[str], write: Callable[[Any], None], mode: str = "w") -> Path:
    """Write ``path`` through a temporary file in its folder, then ``os.replace`` it.

    The file gets the permissions a plain ``open(path, "w")`` would give it (an existing
    file keeps its own; a new one 0666 less the umask), not the temporary file's 0600:
    colleagues who read a lab's shared results folder still can.

    ``write(f)`` receives the open temporary file. If anything fails (a full disk, a
    read-only folder, an exception in ``write``) the temporary file is removed, the old
    ``path`` is left exactly as it was, and ``OSError``/the writer's exception propagates.
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    mode_bits = _file_mode(p)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=folder)
    except OSError as e:  # the folder is not there, or not writable: say so of the file asked for
        raise OSError(e.errno, e.strerror, str(p)) from None
    try:
        kwargs: dict[str, Any] = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, mode, **kwargs) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode_bits)  # mkstemp made it private (0600): the permissions a plain write would give
        os.replace(tmp, p)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, OSError) and e.filename == tmp:  # name the file asked for, not the temporary one
            raise OSError(e.errno, e.strerror, str(p)) from None
        raise
    return p


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """:func:`atomic_write` of a string (UTF-8)."""
    return atomic_write(path, lambda f: f.write(text))
