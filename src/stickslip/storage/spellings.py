"""The kept state of two spellings of one controller made one device's (the upgrades to schema 4 and 5).

Before schema 5 a device's rows were kept under its URL's key (``anc300://h``, ``anc300://h:7230`` and
``anc300://h/`` were three devices) while its lock was its controller's: each spelling kept positions of its
own, and a move through one left the others where the arm no longer was. The upgrade names every device by
its controller (:func:`~.schema.stored_device`) and merges what the spellings kept, by :func:`merge_state`:

* the same value under both: one is kept;
* ``positions``: a joint both kept alike (position and uncertain bounds) keeps it; a joint they kept apart
  is **uncertain over its whole range** until it is referenced again. Neither spelling's position can be
  trusted: the one written last may be the one a move planned from the other's stale position (the very
  fault the upgrade ends), so the time a row was written does not tell which is right. A move's claimed
  range is the span both claims cover; the base tilt is the last written (said when they differ). Each
  spelling's positions as it kept them stay beside, under ``positions (from URL)``;
* ``lock``: a holder is kept over none (the later written of two), the other under ``lock (from URL)``;
* any other key both hold (the controller's identity, named positions) is kept under ``KEY (from URL)``.
"""

from __future__ import annotations

import json
import math
from typing import Any

from ..devices.base import redact_url
from ..joints import JOINTS, coordinate_bound
from .backend import Backend

POSITIONS, LOCK = "positions", "lock"


def merge_state(con: Backend, src: int, dst: int, url: str, key: str, was: str) -> list[str]:
    """Move the state rows of device ``src`` (stored as ``url``) to ``dst`` (named ``key``, stored as ``was`` before
    the upgrade: another spelling); a line per problem the user must know of."""
    held = {str(r[0]): (str(r[1]), str(r[2])) for r in con.execute(
        "SELECT key, value, updated_at FROM device_state WHERE device_id = ?", (dst,))}
    rows = [(str(r[0]), str(r[1]), str(r[2])) for r in con.execute(
        "SELECT key, value, updated_at FROM device_state WHERE device_id = ?", (src,))]
    con.execute("DELETE FROM device_state WHERE device_id = ?", (src,))
    said: list[str] = []
    for name, value, updated in rows:
        if name not in held:
            _put(con, dst, held, name, value, updated)
        elif value == held[name][0]:
            continue  # the same value under both spellings: kept once, nothing lost
        elif name == POSITIONS:
            said += _merge_positions(con, dst, held, (value, updated), (url, was), key)
        elif name == LOCK and _holder(value) and (not _holder(held[name][0]) or updated > held[name][1]):
            _put(con, dst, held, _aside(held, name, was), *held[name])  # the older holder kept beside
            _set(con, dst, held, name, value, updated)
        else:
            _put(con, dst, held, _aside(held, name, url), value, updated)
    return said


def _put(con: Backend, dst: int, held: dict[str, tuple[str, str]], name: str, value: str, updated: str) -> None:
    con.execute("INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, ?, ?, ?)",
                (dst, name, value, updated))
    held[name] = (value, updated)


def _set(con: Backend, dst: int, held: dict[str, tuple[str, str]], name: str, value: str, updated: str) -> None:
    con.execute("UPDATE device_state SET value = ?, updated_at = ? WHERE device_id = ? AND key = ?",
                (value, updated, dst, name))
    held[name] = (value, updated)


def _aside(held: dict[str, tuple[str, str]], name: str, url: str) -> str:
    """A free key for ``name`` as ``url`` kept it: ``KEY (from URL)`` (``, 2`` ... if two spellings redact alike)."""
    kept, again = name, 0
    while kept in held:
        again += 1
        kept = f"{name} (from {redact_url(url)}{'' if again == 1 else f', {again}'})"
    return kept


def _holder(text: str) -> bool:
    try:
        return isinstance(json.loads(text), dict)
    except ValueError:
        return True  # a row that cannot be read is kept where a command reads it (where --unlock releases it)


def _merge_positions(con: Backend, dst: int, held: dict[str, tuple[str, str]], theirs: tuple[str, str],
                     names: tuple[str, str], key: str) -> list[str]:
    """Merge the kept positions ``theirs`` (value, time) of ``url`` into ``dst``'s (``was``'s before the upgrade:
    ``names`` is ``(url, was)``); each as it was kept stays beside, under ``positions (from URL)``."""
    url, was = names
    mine = held[POSITIONS]
    if (first := f"{POSITIONS} (from {redact_url(was)})") not in held:  # a third spelling: kept with the second's
        _put(con, dst, held, first, *mine)
    _put(con, dst, held, _aside(held, POSITIONS, url), *theirs)
    a, b = _readable(mine[0]), _readable(theirs[0])
    if a is None or b is None:  # a row no command can read: it stays the kept one, and refuses until recorded anew
        if b is not None:
            _set(con, dst, held, POSITIONS, *theirs)  # the readable one, every joint uncertain (below)
            a, b = b, {}
        elif a is not None:
            b = {}
        else:
            return [f"{key}: neither {redact_url(url)} nor {was} kept positions a command can read; record them "
                    f"anew (`stickslip where -d {key} --set ...`)"]
    newer, older = (b, a) if b and theirs[1] > mine[1] else (a, b)
    merged, apart = merge_positions(newer, older, "#" in key,
                                    f"{redact_url(url)} and {was}, one controller, kept two positions of it "
                                    "before the upgrade to schema 5")
    _set(con, dst, held, POSITIONS, json.dumps(merged), max(mine[1], theirs[1]))
    said = []
    if apart:
        joints = " and ".join(map(str, apart))
        said.append(
            f"{key}: the positions kept under {redact_url(url)} and {was} disagree on joint(s) {joints}: "
            "neither can be trusted (a move through one spelling planned from the other's old position), so "
            f"joint(s) {joints} are uncertain over their whole range until referenced again "
            f"(`stickslip where -d {key} --set J=Q`); each spelling's positions are kept beside, under "
            f"'positions (from ...)'"
        )
    if older and (newer.get("theta"), newer.get("psi")) != (older.get("theta"), older.get("psi")):
        said.append(f"{key}: the base tilt kept under the two spellings differs: the one written last is kept "
                    f"(theta = {newer.get('theta')} rad, psi = {newer.get('psi')} rad); set it with "
                    f"`stickslip where -d {key} --theta ... --psi ...` if it is not the arm's")
    return said


def _readable(text: str) -> dict[str, Any] | None:
    try:
        raw = json.loads(text)
    except ValueError:
        return None
    return raw if isinstance(raw, dict) and isinstance(raw.get("positions"), dict) else None


def merge_positions(newer: dict[str, Any], older: dict[str, Any], arm: bool, why: str) -> tuple[dict[str, Any],
                                                                                               list[int]]:
    """The positions JSON of one controller from two spellings' (``older``: ``{}`` if it could not be read), and
    the joints they kept apart (now uncertain: ``why``).

    ``newer`` is kept, but for a joint whose position or uncertain bounds differ: uncertain over its whole
    range. The store does not know an arm's joints: the MM3A's range is taken (an arm opened by its URL alone),
    unless the key names a rig arm (``arm``) or a kept value lies beyond the MM3A's stops; then the bounds are
    every arm's coordinate bound, which reading them (``devices.positions.load_state``) turns into the arm's
    own whole range. (A rig file's only arm, kept under the bare key, with a joint wider than the MM3A's and
    values inside the MM3A's range, gets the MM3A's range: uncertain, refused until referenced, but its bounds
    narrower than its stops.) Claims: per joint, the span of both.
    """
    merged = json.loads(json.dumps(newer))
    apart = []
    for j in sorted({*_section(newer, "positions"), *_section(older, "positions")}, key=str):
        if _entry(newer, j) == _entry(older, j) and _entry(newer, j) != (None, None):
            continue
        apart.append(int(j) if str(j).isdigit() else j)
        values = [v for raw in (newer, older) for v in _values(raw, j)]
        spec = JOINTS.get(int(j)) if str(j) in ("1", "2", "3") else None
        if spec is not None and not arm and all(spec.contains(v) for v in values):
            lo, hi = spec.lower, spec.upper
        else:
            bound = coordinate_bound(int(j)) if spec is not None else 0.0
            lo, hi = -bound, bound
        merged.setdefault("uncertain", {})[str(j)] = [lo, hi]
        merged.setdefault("why", {})[str(j)] = why
    for j in {*_section(newer, "claim"), *_section(older, "claim")}:
        values = [float(v) for raw in (newer, older) for v in _pair(_section(raw, "claim").get(j))]
        if values:
            merged.setdefault("claim", {})[j] = [min(values), max(values)]
    return merged, [j for j in apart if isinstance(j, int)]


def _section(raw: dict[str, Any], name: str) -> dict[str, Any]:
    value = raw.get(name)
    return value if isinstance(value, dict) else {}


def _pair(value: Any) -> list[float]:
    if isinstance(value, list) and len(value) == 2 and all(_number(v) for v in value):
        return [float(v) for v in value]
    return []


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _entry(raw: dict[str, Any], j: str) -> tuple[Any, Any]:
    """What a joint's kept position is: its position and uncertain bounds, as kept (``None``: not kept)."""
    return _section(raw, "positions").get(j), _section(raw, "uncertain").get(j)


def _values(raw: dict[str, Any], j: str) -> list[float]:
    q = _section(raw, "positions").get(j)
    return ([float(q)] if isinstance(q, (int, float)) and _number(q) else []) + _pair(_section(raw, "uncertain").get(j))
