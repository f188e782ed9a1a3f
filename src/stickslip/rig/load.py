"""Read and check a rig file (TOML, docs/rig.md) into a :class:`~.model.Rig`.

Every value is checked on load; the first problem raises :class:`RigError`, one line
``FILE:LINE: KEY: reason`` (tomllib gives no positions, so the line is found in the text:
:func:`line_of`). Quantities are strings with units (``"21mm"``, ``"-90deg"``,
``"200um"``) or bare SI numbers. An arm of kind ``"mm3a"`` takes the joints and the
geometry it does not give from the MM3A's description shipped with the package
(:data:`MM3A_FILE`, read by :func:`mm3a_rig`).
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np

from ..devices.base import SECRET_OPTIONS, device_key, redact_url
from ..joints import MAX_STROKE, MAX_TURN, MM3A_FILE
from ..kinematics import Geometry
from ..records import FILE_URL_DATABASE, is_file_url, read_text_bounded
from ..units import UnitError, parse_angle, parse_length
from .model import (
    ARM_KINDS,
    SHAPES,
    Arm,
    Box,
    Cylinder,
    HalfSpace,
    Joint,
    Mount,
    NamedPosition,
    Rig,
    Vec,
    Volume,
    rotation_matrix,
)

__all__ = ["MM3A_FILE", "RigError", "line_of", "load_rig", "mm3a_rig", "parse_rig"]

MAX_RIG_BYTES = 1_000_000
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9 _.\-]{0,39}$")
_ENV_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")
_MAX_SIZE = 10.0  # m: no rig is 10 m across; catches unit slips
_BARE = re.compile(r"^\s*[-+]?(?:\d[\d_]*\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*$")  # a number without a unit
_MAX_ANGLE = 20.0 * math.pi  # rad: ten turns; beyond, a float angle's sine is noise (1e300 deg turns any way)


class RigError(ValueError):
    """A rig file cannot be used: one line naming the file, the line, the key and the reason."""


Key = tuple[str | int, ...]


def _show(key: Key) -> str:
    out = ""
    for part in key:
        out += f"[{part + 1}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


_HEADER = re.compile(r"^\s*(?P<open>\[\[?)\s*(?P<name>[^\[\]]+?)\s*\]\]?\s*(?:#.*)?$")
_KEY_PART = r"(?:\"[^\"]*\"|'[^']*'|[A-Za-z0-9_\-]+)"
_KEY_LINE = re.compile(r"^\s*(?P<key>" + _KEY_PART + r"(?:\s*\.\s*" + _KEY_PART + r")*)\s*=")


def _parts(raw: str) -> tuple[str, ...]:
    found = re.findall(r"\"([^\"]*)\"|'([^']*)'|([A-Za-z0-9_\-]+)", raw)
    return tuple(a or b or c for a, b, c in found)


def line_of(text: str, key: Key) -> int | None:
    """The line of ``text`` that sets ``key`` (or opens its table), else of its nearest parent; ``None`` if none.

    ``key`` is a path with array indices, e.g. ``("arm", 1, "joint", 0, "range")`` for
    the first ``[[arm.joint]]`` of the second ``[[arm]]``'s ``range``.
    """
    lines: dict[Key, int] = {}
    counts: dict[Key, int] = {}
    table: Key = ()
    for n, line in enumerate(text.splitlines(), start=1):
        m = _HEADER.match(line)
        if m:
            path: Key = ()
            names = _parts(m.group("name"))
            for name in names[:-1]:  # an outer array of tables means its last element
                path = path + (name,)
                if path in counts:
                    path = path + (counts[path] - 1,)
            path = path + names[-1:]
            if m.group("open") == "[[":
                index = counts.get(path, 0)
                counts[path] = index + 1
                path = path + (index,)
            table = path
            lines.setdefault(table, n)
            continue
        m = _KEY_LINE.match(line)
        if m:
            lines.setdefault(table + _parts(m.group("key")), n)
    for cut in range(len(key), 0, -1):
        if key[:cut] in lines:
            return lines[key[:cut]]
    return None


class _Values:
    """Checks one value each; ``fail(key, why)`` makes the one-line error naming its line."""

    def __init__(self, text: str, path: str) -> None:
        self.text = text
        self.path = path

    def fail(self, key: Key, why: str) -> RigError:
        line = line_of(self.text, key)
        where = f"{self.path}:{line}" if line else self.path
        return RigError(f"{where}: {_show(key)}: {why}")

    # -- values
    def table(self, doc: dict[str, Any], key: Key, known: tuple[str, ...]) -> dict[str, Any]:
        if not isinstance(doc, dict):
            raise self.fail(key, f"must be a table, not {_kind(doc)}")
        for k in doc:
            if k not in known:
                raise self.fail(key + (k,), f"unknown key (known here: {', '.join(known)})")
        return doc

    def string(self, value: Any, key: Key, pattern: re.Pattern[str] | None = None) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, not {_kind(value)}")
        if pattern is not None and not pattern.match(value):
            raise self.fail(key, f"{value!r} must be 1-40 letters, digits, spaces, _ . or -")
        return value

    def quantity(self, value: Any, key: Key, kind: str, positive: bool = False, nonneg: bool = False) -> float:
        parse: Callable[[str | float], float] = parse_angle if kind == "angle" else parse_length
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise self.fail(key, f"must be {_NOUN[kind]} such as {_EXAMPLE[kind]}, not {_kind(value)}")
        try:
            v = parse(value)
        except UnitError as e:
            raise self.fail(key, str(e)) from None
        if not math.isfinite(v):
            raise self.fail(key, f"{value!r} is not finite")
        if kind == "length" and abs(v) > _MAX_SIZE:
            raise self.fail(key, f"{value!r} is {v:.3g} m: more than {_MAX_SIZE:g} m (a unit slip?)")
        if kind == "length" and abs(v) > MAX_STROKE and _BARE.match(str(value)):  # tool = [0, 0, -5]: 5 mm meant
            raise self.fail(key, f"{value!r} has no unit, so it is {value} m: more than a metre; write its unit "
                            f"(\"{value}mm\" for millimetres, \"{value}m\" if metres are meant)")
        if kind == "angle" and abs(v) > 2.0 * math.pi and _BARE.match(str(value)):
            raise self.fail(key, f"{value!r} has no unit, so it is {value} rad ({math.degrees(v):.4g} deg): more "
                            f"than a turn; write its unit (\"{value}deg\" for degrees)")
        if kind == "angle" and abs(v) > _MAX_ANGLE:
            raise self.fail(key, f"{value!r} is {math.degrees(v):.3g} deg: more than ten turns (a unit slip?)")
        if positive and not v > 0:
            raise self.fail(key, f"{value!r} must be greater than 0")
        if nonneg and v < 0:
            raise self.fail(key, f"{value!r} must not be negative")
        return v

    def vector(self, value: Any, key: Key, kind: str | None) -> Vec:
        if not isinstance(value, list) or len(value) != 3:
            raise self.fail(key, "must be an array of 3 values (x, y, z)")
        if kind is None:
            out = []
            for i, v in enumerate(value):
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise self.fail(key, f"component {i + 1} must be a finite number")
                out.append(float(v))
            return (out[0], out[1], out[2])
        a, b, c = (self.quantity(v, key, kind) for v in value)
        return (a, b, c)

    def direction(self, value: Any, key: Key) -> Vec:
        v = np.asarray(self.vector(value, key, None))
        big = float(np.max(np.abs(v)))
        if big == 0.0:
            raise self.fail(key, "must not be the zero vector")
        w = v / big  # scaled first: the norm of [1e308, 1e308, 0] overflows (a zero direction), of 1e-320 underflows
        u = w / float(np.linalg.norm(w))
        return (float(u[0]), float(u[1]), float(u[2]))

    def integer(self, value: Any, key: Key, lo: int, hi: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise self.fail(key, f"must be a whole number from {lo} to {hi}")
        return value

    def pair(self, value: Any, key: Key, unit: str) -> tuple[float, float]:
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(key, "must be [lower, upper]")
        lo, hi = (self.quantity(v, key, unit) for v in value)
        if not lo < hi:
            raise self.fail(key, "lower must be less than upper")
        return lo, hi

    def arms_apart(self, arms: tuple[Arm, ...]) -> None:
        """Each arm a name of its own (whatever its case) and, on a controller shared, channels of its own."""
        seen: dict[str, str] = {}  # casefolded -> as written: "Probe" and "probe" are one name to a person
        # (controller, channel map, channel) -> the arm it drives: a channel is the URL's joint number, so
        # two arms on one controller differ in their channels, or in the URL's channel map (channels=...).
        # The controller is the one its URL opens (_controller_identity): sim:// and sim://?seed=0, or
        # mm3a:///COM3 and mm3a://com3?timeout=5, are one controller
        channels: dict[tuple[str, str, int], str] = {}
        for i, a in enumerate(arms):
            if a.name.casefold() in seen:
                raise self.fail(("arm", i, "name"), f"a second arm named {a.name!r}" + _case(seen[a.name.casefold()],
                                                                                          a.name))
            seen[a.name.casefold()] = a.name
            try:
                controller = (_controller_identity(a.controller), _channel_map(a.controller))
            except ValueError as e:
                raise self.fail(("arm", i, "controller"), str(e)) from None
            for j in a.joints:
                other = channels.get((*controller, j.channel))
                if other is not None:
                    raise self.fail(("arm", i, "controller"), f"arm {other!r} drives channel {j.channel} of this "
                                    f"controller ({controller[0]}) already (joint {j.number} of {a.name!r}): two "
                                    "arms on one controller need channels of their own")
                channels[(*controller, j.channel)] = a.name


class _Reader(_Values):
    """Reads one document: the rig, its arms, joints, volumes and named positions."""

    def rig(self, doc: dict[str, Any], base: Rig | None) -> Rig:
        self.table(doc, (), ("name", "n_sigma", "arm_distance", "stage", "database", "arm", "volume", "position"))
        name = self.string(doc.get("name", Path(self.path).stem), ("name",))
        n_sigma = doc.get("n_sigma", 3.0)
        if isinstance(n_sigma, bool) or not isinstance(n_sigma, (int, float)) or not 0 <= n_sigma <= 10:
            raise self.fail(("n_sigma",), "must be a number from 0 to 10 (standard deviations)")
        arm_distance = self.quantity(doc.get("arm_distance", 0.0), ("arm_distance",), "length", nonneg=True)
        stage = self.table(doc.get("stage", {}), ("stage",), ("tilt",))
        tilt = self.quantity(stage.get("tilt", 0.0), ("stage", "tilt"), "angle")
        if abs(tilt) > math.pi / 2:
            raise self.fail(("stage", "tilt"), "must be within ±90 deg")
        arms_raw = doc.get("arm")
        if not isinstance(arms_raw, list) or not arms_raw:
            raise self.fail(("arm",), "a rig needs at least one [[arm]]")
        arms = tuple(self.arm(a, ("arm", i), base) for i, a in enumerate(arms_raw))
        self.arms_apart(arms)
        vols_raw = doc.get("volume", [])
        if not isinstance(vols_raw, list):
            raise self.fail(("volume",), "must be an array of tables ([[volume]])")
        volumes = tuple(self.volume(v, ("volume", i), tilt) for i, v in enumerate(vols_raw))
        vseen: dict[str, str] = {}
        for i, v in enumerate(volumes):
            if v.name.casefold() in vseen:
                raise self.fail(("volume", i, "name"), f"a second volume named {v.name!r}" + _case(
                    vseen[v.name.casefold()], v.name))
            vseen[v.name.casefold()] = v.name
        pos_raw = doc.get("position", [])
        if not isinstance(pos_raw, list):
            raise self.fail(("position",), "must be an array of tables ([[position]])")
        by_name = {a.name: a for a in arms}
        positions = tuple(self.position(p, ("position", i), by_name, arms[0].name) for i, p in enumerate(pos_raw))
        pseen: set[tuple[str, str]] = set()
        for i, p in enumerate(positions):
            if (p.arm, p.name) in pseen:
                raise self.fail(("position", i, "name"), f"arm {p.arm!r} has a second position named {p.name!r}")
            pseen.add((p.arm, p.name))
        database = self.database(doc["database"]) if "database" in doc else None
        return Rig(self.path, name, arms, volumes, positions, arm_distance, tilt, float(n_sigma), database)

    def database(self, value: Any) -> str:
        """The rig's history: an SQLite file (relative to the rig file's folder) or a postgresql:// URL, no password."""
        text = self.string(value, ("database",))
        head, sep, rest = text.partition("://")
        if is_file_url(text) and not sep:
            raise self.fail(("database",), FILE_URL_DATABASE)
        if not sep or len(head) < 2:  # a path (a one-letter "scheme" is a Windows drive)
            p = Path(text).expanduser()
            return str(p if p.is_absolute() else Path(self.path).parent / p)
        if head.lower() not in DATABASE_SCHEMES:
            raise self.fail(("database",), f"{head}:// is not a database stickslip can use: give a file path or "
                            "a postgresql:// URL")
        userinfo, at, _ = rest.partition("?")[0].rpartition("@")
        query = rest.partition("?")[2]
        if (at and ":" in userinfo) or redact_url(text) != text or any(
                "pass" in o.partition("=")[0].lower() for o in query.split("&") if "=" in o):
            raise self.fail(("database",), "no password in the rig file: give it in $PGPASSWORD or ~/.pgpass "
                            "(docs/storage.md)")
        return text

    def arm(self, raw: Any, key: Key, base: Rig | None) -> Arm:
        doc = self.table(raw, key, (
            "name", "kind", "controller", "password_env", "password_keyring", "calibration", "tuning", "radius",
            "mount", "geometry", "axes", "tool", "home", "joint",
        ))
        if "name" not in doc:
            raise self.fail(key, "an arm needs a name")
        name = self.string(doc["name"], key + ("name",), _NAME)
        kind = self.string(doc.get("kind", "mm3a"), key + ("kind",))
        if kind not in ARM_KINDS:
            raise self.fail(key + ("kind",), f"{kind!r} is no arm kind (the kinds: {', '.join(ARM_KINDS)})")
        controller = self.controller(doc, key)
        penv, keyring = self.credentials(doc, key)
        files = {}
        for f in ("calibration", "tuning"):
            files[f] = self.string(doc[f], key + (f,)) if f in doc else None
        radius = self.quantity(doc.get("radius", 0.0), key + ("radius",), "length", nonneg=True)
        m = self.table(doc.get("mount", {}), key + ("mount",), ("origin", "rotation"))
        mount = Mount(self.vector(m.get("origin", [0, 0, 0]), key + ("mount", "origin"), "length"),
                      self.vector(m.get("rotation", [0, 0, 0]), key + ("mount", "rotation"), "angle"))
        template = base.arms[0] if base is not None and kind == "mm3a" else None
        geometry = None
        axes: tuple[Vec, Vec, Vec] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
        tool: Vec = (0.0, 0.0, -0.01)
        if kind == "mm3a":
            geometry = self.mm3a_geometry(doc, key, template)
        else:
            axes, tool = self.xyz_frame(doc, key, axes, tool)
        joints = self.joints(doc, key, kind, template)
        home = self.home(doc, key, joints, template)
        return Arm(name, kind, controller, joints, mount, geometry, axes, tool, radius, files["calibration"],
                   files["tuning"], penv, keyring, home)

    def controller(self, doc: dict[str, Any], key: Key) -> str:
        """The arm's controller URL: present, a URL, and with no password in it."""
        if "controller" not in doc:
            raise self.fail(key, "an arm needs a controller URL (e.g. controller = \"sim://\")")
        controller = self.string(doc["controller"], key + ("controller",))
        if redact_url(controller) != controller or _has_secret(controller):
            raise self.fail(key + ("controller",), "no password in the rig file: use password_env or "
                            "password_keyring (docs/rig.md)")
        if "://" not in controller and not controller.endswith(":"):
            raise self.fail(key + ("controller",),
                            f"{controller!r} is not a URL such as sim:// or mm3a:///dev/ttyUSB0")
        return controller

    def credentials(self, doc: dict[str, Any], key: Key) -> tuple[str | None, tuple[str, str] | None]:
        """Where the controller's password is found: an environment variable's name, a keyring entry."""
        penv = doc.get("password_env")
        if penv is not None and not _ENV_NAME.match(self.string(penv, key + ("password_env",))):
            raise self.fail(key + ("password_env",), "must be an environment variable's name")
        keyring: tuple[str, str] | None = None
        if "password_keyring" in doc:
            k = self.table(doc["password_keyring"], key + ("password_keyring",), ("service", "user"))
            if "service" not in k or "user" not in k:
                raise self.fail(key + ("password_keyring",), "needs service and user")
            keyring = (self.string(k["service"], key + ("password_keyring", "service")),
                       self.string(k["user"], key + ("password_keyring", "user")))
        return penv, keyring

    def mm3a_geometry(self, doc: dict[str, Any], key: Key, template: Arm | None) -> Geometry:
        """An mm3a arm's geometry (offset, length; m), the template's where the file leaves them out."""
        for xk in ("axes", "tool"):
            if xk in doc:
                raise self.fail(key + (xk,), "belongs to an xyz arm, not an mm3a")
        g = self.table(doc.get("geometry", {}), key + ("geometry",), ("offset", "length"))
        g0 = template.geometry if template is not None and template.geometry is not None else Geometry()
        offset = self.quantity(g.get("offset", g0.offset), key + ("geometry", "offset"), "length")
        length = self.quantity(g.get("length", g0.length), key + ("geometry", "length"), "length", positive=True)
        try:
            return Geometry(offset, length)
        except ValueError as e:
            raise self.fail(key + ("geometry",), str(e)) from None

    def xyz_frame(
        self, doc: dict[str, Any], key: Key, axes: tuple[Vec, Vec, Vec], tool: Vec
    ) -> tuple[tuple[Vec, Vec, Vec], Vec]:
        """An xyz arm's stage directions (unit vectors) and tool offset (m); ``axes``, ``tool`` by default."""
        if "geometry" in doc:
            raise self.fail(key + ("geometry",), "belongs to an mm3a arm; an xyz arm has axes and tool")
        if "axes" in doc:
            ax = doc["axes"]
            if not isinstance(ax, list) or len(ax) != 3:
                raise self.fail(key + ("axes",), "must be 3 directions, one per stage")
            a1, a2, a3 = (self.direction(a, key + ("axes",)) for a in ax)
            axes = (a1, a2, a3)
            if abs(float(np.linalg.det(np.asarray(axes)))) < 1e-6:
                raise self.fail(key + ("axes",), "the 3 stage directions must not lie in one plane")
        if "tool" in doc:
            tool = self.vector(doc["tool"], key + ("tool",), "length")
        return axes, tool

    def home(self, doc: dict[str, Any], key: Key, joints: tuple[Joint, Joint, Joint], template: Arm | None) -> Vec:
        """The arm's home (joints 1, 2, 3; rad or m): the file's, else the template's, else 0 within range."""
        home_raw = doc.get("home")
        if home_raw is None:
            home: Vec = template.home if template is not None else tuple(  # type: ignore[assignment]
                min(max(0.0, j.limits[0]), j.limits[1]) for j in joints)
            return home
        if not isinstance(home_raw, list) or len(home_raw) != 3:
            raise self.fail(key + ("home",), "must be 3 values, joints 1, 2, 3")
        h = [self.quantity(v, key + ("home",), "angle" if j.kind == "rotary" else "length")
             for v, j in zip(home_raw, joints, strict=True)]
        for v, j in zip(h, joints, strict=True):
            if not j.lower <= v <= j.upper:
                raise self.fail(key + ("home",), f"joint {j.number}'s home is outside its range")
        return (h[0], h[1], h[2])

    def joints(self, doc: dict[str, Any], key: Key, kind: str, template: Arm | None) -> tuple[Joint, Joint, Joint]:
        raw = doc.get("joint")
        if raw is None:
            if template is not None:
                return template.joints
            raise self.fail(key, "an xyz arm needs its 3 [[arm.joint]] tables")
        if not isinstance(raw, list) or len(raw) != 3:
            raise self.fail(key + ("joint",), "an arm has 3 joints: give 3 [[arm.joint]] tables")
        out = []
        for i, j in enumerate(raw):
            jk = key + ("joint", i)
            d = self.table(j, jk, ("number", "channel", "sign", "kind", "range", "stops", "soft", "step"))
            number = self.integer(d.get("number", i + 1), jk + ("number",), 1, 3)
            if number != i + 1:
                raise self.fail(jk + ("number",), f"the joints are listed in order: this is joint {i + 1}")
            channel = self.integer(d.get("channel", number), jk + ("channel",), 1, 64)
            sign = d.get("sign", 1)
            if sign not in (1, -1) or isinstance(sign, bool):
                raise self.fail(jk + ("sign",), "must be 1 or -1")
            default_kind = ("rotary" if number < 3 else "prismatic") if kind == "mm3a" else "prismatic"
            jkind = self.string(d.get("kind", default_kind), jk + ("kind",))
            if jkind not in ("rotary", "prismatic"):
                raise self.fail(jk + ("kind",), f"{jkind!r}: a joint is rotary or prismatic")
            if jkind != default_kind:
                raise self.fail(jk + ("kind",), f"joint {number} of an {kind} arm is {default_kind}")
            unit = "angle" if jkind == "rotary" else "length"
            if "range" not in d:
                raise self.fail(jk, "needs its range = [lower, upper]")
            lo, hi = self.pair(d["range"], jk + ("range",), unit)
            if (far := max(abs(lo), abs(hi))) > (bound := MAX_TURN if jkind == "rotary" else MAX_STROKE):
                what = f"{math.degrees(far):.6g} deg: beyond a full turn" if jkind == "rotary" else \
                    f"{far:.6g} m: beyond a metre"
                raise self.fail(jk + ("range",), f"reaches {what} either way, no joint's position (a unit slip?); "
                                f"positions lie within ±{bound:.6g} {'rad' if jkind == 'rotary' else 'm'}")
            stops = d.get("stops", ["lower", "upper"])
            if (not isinstance(stops, list) or any(s not in ("lower", "upper") for s in stops)
                    or len(set(stops)) != len(stops)):
                raise self.fail(jk + ("stops",), "must list the end stops it has: \"lower\", \"upper\"")
            slo, shi = -math.inf, math.inf
            if "soft" in d:
                slo, shi = self.pair(d["soft"], jk + ("soft",), unit)
                if slo < lo or shi > hi:
                    raise self.fail(jk + ("soft",), "the soft limits must lie within the range")
            step = self.quantity(d["step"], jk + ("step",), unit, positive=True) if "step" in d else math.nan
            if step >= hi - lo:
                raise self.fail(jk + ("step",), "a step must be smaller than the joint's range")
            out.append(Joint(number, channel, int(sign), jkind, lo, hi, tuple(stops), slo, shi, step))
        channels = [j.channel for j in out]
        for i, c in enumerate(channels):
            if c in channels[:i]:
                raise self.fail(key + ("joint", i, "channel"), f"channel {c} drives joint {channels.index(c) + 1} "
                                "already: two joints on one channel")
        return (out[0], out[1], out[2])

    def volume(self, raw: Any, key: Key, tilt: float) -> Volume:
        shape = raw.get("shape") if isinstance(raw, dict) else None
        common = ("name", "shape", "margin", "on_stage")
        own = {"box": ("lower", "upper", "rotation"), "cylinder": ("base", "axis", "radius", "height"),
               "half-space": ("point", "normal")}
        if shape not in SHAPES:
            raise self.fail(key + ("shape",), f"{shape!r} is no shape (the shapes: {', '.join(SHAPES)})")
        doc = self.table(raw, key, common + own[str(shape)])
        if "name" not in doc:
            raise self.fail(key, "a volume needs a name")
        name = self.string(doc["name"], key + ("name",), _NAME)
        margin = self.quantity(doc.get("margin", 0.0), key + ("margin",), "length", nonneg=True)
        on_stage = doc.get("on_stage", False)
        if not isinstance(on_stage, bool):
            raise self.fail(key + ("on_stage",), "must be true or false")
        stage = rotation_matrix((tilt, 0.0, 0.0)) if on_stage else np.eye(3)

        def need(k: str) -> Any:
            if k not in doc:
                raise self.fail(key, f"a {shape} needs {k}")
            return doc[k]

        if shape == "box":
            lo = np.asarray(self.vector(need("lower"), key + ("lower",), "length"))
            hi = np.asarray(self.vector(need("upper"), key + ("upper",), "length"))
            if not np.all(lo < hi):
                raise self.fail(key + ("upper",), "each component must exceed lower's")
            rot = self.vector(doc.get("rotation", [0, 0, 0]), key + ("rotation",), "angle")
            r = stage @ rotation_matrix(rot)
            c = stage @ ((lo + hi) / 2.0)
            h = (hi - lo) / 2.0
            return Box(name, _vec(c), _vec(h), margin, tuple(float(x) for x in r.reshape(9)))
        if shape == "cylinder":
            b = stage @ np.asarray(self.vector(need("base"), key + ("base",), "length"))
            ax = stage @ np.asarray(self.direction(need("axis"), key + ("axis",)))
            radius = self.quantity(need("radius"), key + ("radius",), "length", positive=True)
            height = self.quantity(need("height"), key + ("height",), "length", positive=True)
            return Cylinder(name, _vec(b), _vec(ax), radius, height, margin)
        p = stage @ np.asarray(self.vector(need("point"), key + ("point",), "length"))
        n = stage @ np.asarray(self.direction(need("normal"), key + ("normal",)))
        return HalfSpace(name, _vec(p), _vec(n), margin)

    def position(self, raw: Any, key: Key, arms: dict[str, Arm], first: str) -> NamedPosition:
        doc = self.table(raw, key, ("name", "arm", "q1", "q2", "q3", "order"))
        if "name" not in doc:
            raise self.fail(key, "a position needs a name")
        name = self.string(doc["name"], key + ("name",), _NAME)
        arm_name = self.string(doc.get("arm", first), key + ("arm",))
        if arm_name not in arms:
            raise self.fail(key + ("arm",), f"no arm named {arm_name!r} (the arms: {', '.join(arms)})")
        arm = arms[arm_name]
        q: list[float | None] = []
        for j in arm.joints:
            k = f"q{j.number}"
            if k not in doc:
                q.append(None)
                continue
            v = self.quantity(doc[k], key + (k,), "angle" if j.kind == "rotary" else "length")
            lo, hi = j.limits
            if not lo <= v <= hi:
                raise self.fail(key + (k,), f"is outside joint {j.number}'s limits")
            q.append(v)
        given = [j for j in (1, 2, 3) if q[j - 1] is not None]
        if not given:
            raise self.fail(key, "a position needs at least one of q1, q2, q3")
        order_raw = doc.get("order", given)
        if not isinstance(order_raw, list) or not _orders(order_raw, given):
            raise self.fail(key + ("order",), f"must list each joint the position gives ({given}) once")
        return NamedPosition(name, arm_name, (q[0], q[1], q[2]), tuple(int(o) for o in order_raw))


_EXAMPLE = {"angle": "\"-90deg\"", "length": "\"12mm\""}
_NOUN = {"angle": "an angle", "length": "a length"}


def _orders(order: list[Any], given: list[int]) -> bool:
    """Whether ``order`` lists each joint of ``given`` once (whole numbers first: sorted() of [3, "2"] raises)."""
    return all(isinstance(o, int) and not isinstance(o, bool) for o in order) and sorted(order) == given


def _vec(a: Any) -> Vec:
    return (float(a[0]), float(a[1]), float(a[2]))


def _kind(value: object) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
             dict: "a table"}
    for t, name in names.items():
        if isinstance(value, t):
            return name
    return "a date or time"


def _controller_identity(url: str) -> str:
    """Which controller ``url`` drives, for the rig's channel check: its device key (one for a Windows serial port
    however it is written: ``mm3a:///COM3``, ``mm3a://COM3``, ``mm3a://com3``), and a device file that exists here
    through its links (``/dev/serial/by-id/...`` is the ``/dev/ttyUSB0`` it points to)."""
    key = device_key(url)
    parts = urlsplit(key)
    if key.startswith("sim") or (parts.port is not None):
        return key
    port = parts.path or parts.netloc
    if port.startswith("/") and os.path.exists(port):
        port = os.path.realpath(port)
    return f"{parts.scheme}://{port}"


def _case(first: str, second: str) -> str:
    """What a name repeated in another case adds to its message ("" for the same spelling)."""
    return "" if first == second else f" ({first!r} differs only in case: a name means one thing however typed)"


def _channel_map(url: str) -> str:
    """A controller URL's channel map (its last ``channels=`` option, as the backends read it), else ``""``."""
    return parse_qs(urlsplit(url).query).get("channels", [""])[-1]


def _has_secret(url: str) -> bool:
    low = url.lower()
    return any(f"{k}=" in low for k in SECRET_OPTIONS)


DATABASE_SCHEMES = ("postgresql", "postgres")
"""URL schemes the ``database`` key takes (as :data:`stickslip.storage.POSTGRES_SCHEMES`)."""

_TOML_WHERE = re.compile(
    r"^(?P<reason>.*?)\s*\(at (?:line (?P<line>\d+), column (?P<col>\d+)|end of document)\)$", re.S
)


def parse_rig(text: str, path: str = "<rig>", base: Rig | None = None) -> Rig:
    """The :class:`Rig` that TOML ``text`` (read from ``path``) describes; :class:`RigError` otherwise.

    ``base`` gives an ``mm3a`` arm the joints and geometry it leaves out (default: the
    shipped MM3A description, :func:`mm3a_rig`).
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = _TOML_WHERE.match(str(e))
        if m is None:  # pragma: no cover - tomllib's messages end with their place
            raise RigError(f"{path}: not TOML: {e}") from None
        line = m.group("line") or str(max(1, len(text.splitlines())))
        raise RigError(f"{path}:{line}: not TOML: {m.group('reason')}") from None
    return _Reader(text, path).rig(doc, mm3a_rig() if base is None else base)


def load_rig(path: str | Path) -> Rig:
    """Read the rig file at ``path`` (:func:`parse_rig`); :class:`RigError` for an unreadable file too."""
    try:
        text = read_text_bounded(path, "rig", MAX_RIG_BYTES)
    except ValueError as e:
        raise RigError(str(e)) from None
    return parse_rig(text, str(path))


_MM3A: list[Rig] = []


def mm3a_rig() -> Rig:
    """The MM3A's description shipped with the package (:data:`MM3A_FILE`), read once."""
    if not _MM3A:
        text = MM3A_FILE.read_text(encoding="utf-8")
        _MM3A.append(_Reader(text, MM3A_FILE.name).rig(tomllib.loads(text), None))
    return _MM3A[0]
