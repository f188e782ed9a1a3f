"""The reference pages describe the code as it is: every name they cite resolves, every value they state is the code's.

The reference pages are README.md, docs/*.md (the measurement logs ``*-log.md`` record what was so at the
time and are not read), docs/howto/ and docs/devices/. In them, outside fenced blocks (the examples run in
tests/test_docs_examples.py):

* a dotted name in backticks (``stickslip.vision.track``, ``procedures.move.tracked_calibration``,
  ``TrackerParams.focus_warn``, ``ConfirmedStopDetector.log.clocked``) resolves in the package: imported
  and read with getattr, a dataclass's field or an attribute its class sets counts;
* a class or constant name alone in backticks (``CameraLoop``, ``STOP_RETURN_S``) is defined in the package;
* a file a page names (``benchmarks/bench_audio.py``, ``lugre_arm.py``) is in the repository;
* a constant or parameter written with its value next to it (```SIGMA_MAX` = 1e3 rad``, ``(`LOAD_PRIOR`,
  10 %)``, ```model_hold_s` 0.48 s``) has that value in the code, to the digits the page writes;
* a link between the docs (``[x](y.md#anchor)``) reaches a page that exists and a heading on it;
* each of the paper's equations the code cites has one home whose docstring gives its number, and every
  number the code cites is one docs/design.md gives.

Names that are not Python (a JSON key, a rig-file key, Bluesky's ``RE``) are allowed below, each with why.
Runs in about two seconds: it imports the package's modules and reads the pages, nothing more.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import math
import pkgutil
import re
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import Any

import stickslip

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: names in backticks that look dotted but are not the package's Python, and why each is there
NOT_PYTHON = {
    "RE.request_pause()": "Bluesky's RunEngine, as a Bluesky session names it",
    "bp.scan": "bluesky.plans, as a Bluesky session imports it",
    "bps.mv": "bluesky.plan_stubs, as a Bluesky session imports it",
    "ax.figure": "a matplotlib Axes in the page's example",
    "arm.tip.x": "an ophyd component of the example's StickSlipManipulator instance (its tip's pseudo-axis)",
    "arm.tip.y": "an ophyd component of the example's StickSlipManipulator instance (its tip's pseudo-axis)",
    "arm.tip.z": "an ophyd component of the example's StickSlipManipulator instance (its tip's pseudo-axis)",
    "geometry.offset": "a key of the configuration file's [geometry] table (docs/config.md)",
    "geometry.length": "a key of the configuration file's [geometry] table (docs/config.md)",
    "mount.rotation": "a key of a rig file's arm (docs/rig.md)",
    "jacobian.against_view": "a key of `stickslip camera --json`'s output",
    "json.loads": "the standard library",
    "os.replace": "the standard library",
    "str.split": "the standard library",
    "typing.Protocol": "the standard library",
}
#: bare class-like names in backticks that are not the package's, and why
NOT_PACKAGE_NAMES = {
    "DataFrame": "pandas",
    "NaN": "the floating-point value",
    "NullHandler": "the standard library's logging",
    "UserWarning": "a Python builtin",
    "ValueError": "a Python builtin",
    "STICKSLIP_ANC300_PASSWORD": "an environment variable the ANC300 URL reads",
    "STICKSLIP_TODAY": "an environment variable the clock reads",
}
#: a file name with one of these endings is a file, not a dotted Python name
FILE_ENDINGS = (".py", ".json", ".png", ".jpg", ".csv", ".txt", ".toml", ".cff", ".conf", ".db", ".typed", ".md")


def reference_pages() -> list[Path]:
    pages = [ROOT / "README.md", *sorted(p for p in DOCS.glob("*.md") if not p.name.endswith("-log.md"))]
    return pages + sorted((DOCS / "howto").glob("*.md")) + sorted((DOCS / "devices").glob("*.md"))


def prose(page: Path) -> str:
    """The page without its fenced blocks."""
    return re.sub(r"^```.*?^```", "", page.read_text(encoding="utf-8"), flags=re.S | re.M)


def cited(pattern: str) -> dict[str, list[str]]:
    """Every backticked text matching ``pattern`` (whole), with the pages that cite it."""
    found: dict[str, list[str]] = {}
    for page in reference_pages():
        for m in re.finditer(r"`([^`\n]+)`", prose(page)):
            text = m.group(1).strip()
            if re.fullmatch(pattern, text):
                found.setdefault(text, []).append(page.relative_to(ROOT).as_posix())
    return found


@cache
def modules() -> dict[str, ModuleType]:
    found = {"stickslip": stickslip}
    for info in pkgutil.walk_packages(stickslip.__path__, "stickslip."):
        found[info.name] = importlib.import_module(info.name)
    return found


UNKNOWN = object()  # an attribute that exists, of a value not known without an instance
MISSING = object()  # no such attribute


def _set_by_class(cls: type, part: str) -> Any:
    """What a class's methods set ``self.part`` to: the class it is made of if the source says, else UNKNOWN."""
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return MISSING
    made = re.search(rf"self\.{part}\s*(?::[^=\n]+)?=\s*(\w+)\(", source)
    if made:
        return vars(inspect.getmodule(cls)).get(made.group(1), UNKNOWN)
    return UNKNOWN if re.search(rf"self\.{part}\s*(?::[^=\n]+)?=[^=]", source) else MISSING


def attribute(obj: Any, part: str) -> Any:
    """``obj.part``: the value, UNKNOWN where it exists without a value known, MISSING where it does not exist."""
    if obj is UNKNOWN:
        return UNKNOWN
    if hasattr(obj, part):
        return getattr(obj, part)
    if isinstance(obj, type):
        if dataclasses.is_dataclass(obj):
            fields = {f.name: f for f in dataclasses.fields(obj)}
            if part in fields:
                return UNKNOWN
        if any(part in getattr(base, "__annotations__", {}) for base in obj.__mro__):
            return UNKNOWN
        return _set_by_class(obj, part)
    return MISSING


def walk(obj: Any, parts: list[str]) -> Any:
    for part in parts:
        obj = attribute(obj, part)
        if obj is MISSING:
            break
    return obj


def ours(obj: Any) -> bool:
    """A constant, class, function or module of the package's, not one a module imported (``json``, ``bps``)."""
    if obj is MISSING:
        return False
    where = obj.__name__ if isinstance(obj, ModuleType) else getattr(obj, "__module__", "stickslip")
    return isinstance(where, str) and where.split(".")[0] == "stickslip"


def resolve(name: str) -> Any:
    """What a dotted name the docs cite is in the package, or MISSING.

    Tried in order: the package's module it names (``stickslip.x.y`` or ``x.y`` relative to the package), a module
    by its last names (``inside.Held``: ``stickslip.audio.confirm.inside``), a name any module defines
    (``ClockedParams.model_onset``)."""
    parts = name.removesuffix("()").split(".")
    parts = parts[1:] if parts[0] == "stickslip" else parts
    mods = modules()
    for k in range(len(parts), 0, -1):
        mod = mods.get("stickslip." + ".".join(parts[:k]))
        if mod is not None and (got := walk(mod, parts[k:])) is not MISSING:
            return got
    for k in range(len(parts), 0, -1):
        for modname, mod in mods.items():
            if modname.split(".")[-k:] == parts[:k] and (got := walk(mod, parts[k:])) is not MISSING:
                return got
    for mod in mods.values():
        top = vars(mod).get(parts[0], MISSING)
        if ours(top) and (got := walk(top, parts[1:])) is not MISSING:
            return got
    return MISSING


def test_every_dotted_name_the_reference_cites_resolves() -> None:
    names = cited(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)+(\(\))?")
    assert len(names) > 200  # the pattern still finds the names (287 at writing)
    files = [n for n in names if n.endswith(FILE_ENDINGS)]
    stale = [f"{n} ({', '.join(names[n])})" for n in names
             if n not in files and n not in NOT_PYTHON and resolve(n) is MISSING]
    assert not stale, f"names the reference pages cite that the package does not have: {stale}"
    assert set(NOT_PYTHON) <= set(names), f"allowed but no longer cited: {set(NOT_PYTHON) - set(names)}"
    came = [n for n in NOT_PYTHON if resolve(n) is not MISSING]  # the package's now: check it, do not allow it
    assert not came, came


def test_every_class_or_constant_name_the_reference_cites_is_defined() -> None:
    names = cited(r"([A-Z][a-z]+[A-Z]\w*|[A-Z][A-Z0-9]*_[A-Z0-9_]+)(\(.*\))?")
    defined: set[str] = set()
    for mod in modules().values():
        defined |= set(vars(mod))
    stale = [f"{n} ({', '.join(p)})" for n, p in names.items()
             if (bare := n.split("(")[0]) not in defined and bare not in NOT_PACKAGE_NAMES]
    assert not stale, f"class or constant names the package does not define: {stale}"
    assert set(NOT_PACKAGE_NAMES) <= {n.split("(")[0] for n in names}, "an allowed name is no longer cited"


def test_every_file_the_reference_names_is_in_the_repository() -> None:
    tracked = {p.name for folder in ("benchmarks", "tests", "src") for p in (ROOT / folder).rglob("*.py")}
    scripts = cited(r"\w+\.py")
    missing = [f"{n} ({p})" for n, p in scripts.items() if n not in tracked]
    paths = cited(r"(src|tests|benchmarks|docs)/[\w./-]+(\s.*)?")
    missing += [f"{n} ({p})" for n, p in paths.items() if not (ROOT / n.split()[0]).exists()]
    assert len(scripts) + len(paths) > 30
    assert not missing, missing


#: what a unit the pages write a value in is, in the code's SI (a count, a ratio, dB, px: 1)
UNITS = {"s": 1.0, "ms": 1e-3, "min": 60.0, "%": 0.01, "MiB": 2.0**20, "µm": 1e-6, "um": 1e-6, "mm": 1e-3,
         "m": 1.0, "mrad": 1e-3, "rad": 1.0, "px": 1.0, "dB": 1.0, "spreads": 1.0, "Hz": 1.0, "": 1.0}
_NUMBER = r"(-?\d+(?:\.\d+)?(?:e-?\d+)?)"
_VALUE = re.compile(rf"`([A-Za-z_][\w.]*)`\s*(?:=\s*|,\s*|\(\s*)?{_NUMBER}(?:\s?(MiB|mrad|min|ms|µm|um|mm|rad|px|dB|"
                    rf"spreads|Hz|s|m|%)(?![\w.]))?")


@cache
def parameter_defaults() -> dict[str, list[float]]:
    """The default of every numeric field of the package's parameter records (``*Params``), by field name."""
    found: dict[str, list[float]] = {}
    for mod in modules().values():
        for cls in vars(mod).values():
            if isinstance(cls, type) and cls.__name__.endswith("Params") and dataclasses.is_dataclass(cls):
                for f in dataclasses.fields(cls):
                    if type(f.default) in (int, float):
                        found.setdefault(f.name, []).append(float(f.default))
    return found


def stated_values() -> list[tuple[str, str, float, float, list[float]]]:
    """(page, name, value as written in SI, its half last digit in SI, the code's values) of each name-value pair."""
    out = []
    for page in reference_pages():
        for m in _VALUE.finditer(prose(page)):
            name, number, unit = m.group(1), m.group(2), m.group(3) or ""
            if "." in name or name.isupper():
                got = resolve(name)
                code = [float(got)] if type(got) in (int, float) else []
            else:
                code = parameter_defaults().get(name, [])
            if code:
                digits = len(number.split("e")[0].split(".")[1]) if "." in number.split("e")[0] else 0
                exp = int(number.split("e")[1]) if "e" in number else 0
                scale = UNITS[unit]
                out.append((page.name, name, float(number) * scale, 0.5 * 10.0 ** (exp - digits) * scale, code))
    return out


def test_every_value_the_reference_states_next_to_its_name_is_the_codes() -> None:
    stated = stated_values()
    assert len(stated) >= 20  # the pattern still finds them (22 at writing)
    wrong = [f"{page}: `{name}` {value:g} against the code's {code}" for page, name, value, half, code in stated
             if not any(math.isclose(value, c, abs_tol=half * 1.0001) for c in code)]
    assert not wrong, wrong


def slugs(page: Path) -> set[str]:
    """The anchors of a page's headings, as mkdocs' ``toc`` makes them (a repeated heading gets ``_1``, ``_2``)."""
    import unicodedata

    found: set[str] = set()
    for m in re.finditer(r"^#{1,6}\s+(.*?)\s*#*\s*$", prose(page), flags=re.M):
        text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", re.sub(r"<[^>]+>", "", m.group(1))).replace("`", "")
        text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
        slug = re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", text).strip().lower())
        n, unique = 0, slug
        while unique in found:
            n += 1
            unique = f"{slug}_{n}"
        found.add(unique)
    return found | set(re.findall(r'id="([^"]+)"', prose(page)))


def test_every_link_between_the_docs_reaches_a_page_and_a_heading_on_it() -> None:
    """Every page (the logs too: a link there is read today) links only to files and headings that exist."""
    links, broken = 0, []
    for page in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]:
        for m in re.finditer(r"\[[^\]]*\]\(([^)\s]+)\)", prose(page)):
            target = m.group(1)
            if re.match(r"[a-z]+:", target):  # https:, mailto:
                continue
            links += 1
            file, _, anchor = target.partition("#")
            path = (page.parent / file) if file else page
            if not path.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and path.suffix == ".md" and anchor not in slugs(path):
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert links > 100  # the pattern still finds the links (119 at writing)
    assert not broken, broken


#: the one home of each of the paper's equations the code cites: its docstring gives the number
EQUATION_HOMES = {
    1: "stickslip.measurements.rows.Traverse.gamma",
    2: "stickslip.models.paper.eta",
    3: "stickslip.models.paper.gamma_prismatic",
    4: "stickslip.calibration.paper._paper_prismatic",
    5: "stickslip.calibration.paper._paper_prismatic",
    6: "stickslip.calibration.paper._paper_prismatic",
    7: "stickslip.models.paper.gamma_rotary",  # design.md: (Eqs. 7, 8), one formula
    8: "stickslip.models.paper.gamma_rotary",
    9: "stickslip.calibration.inversion.eq9_printed",
}


def equation_numbers(text: str) -> set[int]:
    """The equation numbers a text cites: ``Eq. 3``, ``Eq. (8)``, ``Eqs. (4)–(6)``, ``Eqs. 3/8``, ``Eqs. 7, 8``."""
    found: set[int] = set()
    for m in re.finditer(r"\bEqs?\.\s*((?:\(?\d+\)?\s*(?:[-–/,]|and)?\s*)+)", text):
        numbers = [int(n) for n in re.findall(r"\d+", m.group(1))]
        if re.search(r"\d\)?\s*[-–]\s*\(?\d", m.group(1)):  # a range
            numbers = list(range(numbers[0], numbers[-1] + 1))
        found |= set(numbers)
    return found


def test_every_equation_the_code_cites_is_one_design_md_numbers_and_has_one_home() -> None:
    design = equation_numbers((DOCS / "design.md").read_text(encoding="utf-8"))
    assert design >= {1, 2, 3, 4, 5, 6, 7, 8, 9}, design
    cited: dict[int, list[str]] = {}
    for path in sorted((ROOT / "src" / "stickslip").rglob("*.py")):
        for n in equation_numbers(path.read_text(encoding="utf-8")):
            cited.setdefault(n, []).append(path.relative_to(ROOT).as_posix())
    assert set(cited) <= design, {n: cited[n] for n in set(cited) - design}
    assert set(cited) <= set(EQUATION_HOMES), {n: cited[n] for n in set(cited) - set(EQUATION_HOMES)}
    for n, home in EQUATION_HOMES.items():
        assert n in equation_numbers(inspect.getdoc(resolve(home)) or ""), (n, home)


def test_the_printed_eq9_is_stated_once_in_the_package() -> None:
    """Its coefficients live in ``EQ9_PRINTED`` (and its docstring); elsewhere the code names it, not restates it."""
    where = [p.relative_to(ROOT).as_posix() for p in sorted((ROOT / "src" / "stickslip").rglob("*.py"))
             if "6.42e-7" in p.read_text(encoding="utf-8")]
    assert where == ["src/stickslip/calibration/inversion.py"], where


def top_keywords(call: str) -> list[str]:
    """The keyword arguments of a call written ``f(a, k=...)``, not those of the calls inside it."""
    depth, start, found = 0, 0, []
    for i, ch in enumerate(call):
        if ch in "([{":
            depth += 1
            start = i + 1 if depth == 1 else start
        elif ch in ")]}":
            depth -= 1
        elif ch == "," and depth == 1:
            start = i + 1
        if depth == 1 and ch == "=" and call[i + 1:i + 2] != "=" and re.fullmatch(r"\s*\w+\s*", call[start:i]):
            found.append(call[start:i].strip())
    return found


def test_every_call_the_reference_writes_passes_keywords_the_code_takes() -> None:
    """``ConfirmParams(clocked=None)``, ``plan_reach(..., step_model="constant")``: the keyword is a parameter."""
    calls = cited(r"[A-Za-z_][\w.]*\(.*\w\s*=.*\)")
    assert len(calls) > 15  # the pattern still finds them (22 at writing)
    wrong = []
    for call, pages in calls.items():
        obj = resolve(call.split("(")[0])
        if not callable(obj) or isinstance(obj, ModuleType):
            continue
        params = inspect.signature(obj).parameters
        if any(p.kind == p.VAR_KEYWORD for p in params.values()):
            continue
        wrong += [f"{call} ({', '.join(pages)}): {k}" for k in top_keywords(call) if k not in params]
    assert not wrong, wrong


def test_the_exit_codes_the_threat_model_lists_are_the_codes() -> None:
    from stickslip.cli._common import EXIT_CODES

    text = (DOCS / "threat-model.md").read_text(encoding="utf-8")
    table = {int(code) for code in re.findall(r"^\| (\d+) \|", text.split("## ")[0], flags=re.M)}
    assert table == set(EXIT_CODES), (table, set(EXIT_CODES))
