"""The package stays a house a newcomer can read: no function over 60 lines, no class over 300 (issue 35).

A function's or class's length is counted from its first statement after the docstring to its
last line, so a long docstring or a long signature (a typer command's option list) does not
count; the body does. The walk reads ``src/stickslip`` with :mod:`ast` and runs nothing.
"""

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "stickslip"

MAX_FUNCTION_LINES = 60
MAX_CLASS_LINES = 300

# Over the limits today and being restructured by other work at the same time (the calibration
# and vision packages), so not touched here: listed so this test holds
# meanwhile. An entry is (folder or module, qualified name), so a move inside its folder keeps it;
# when its owner brings it under the limit, the entry must go (test_allow_list_is_not_stale).
ALLOWED = {
    # calibration/: the calibration groups its traverses once (issue 35 item 4)
    ("calibration/", "read_ext_fields"),
    ("calibration/", "update_calibration"),
    ("calibration/", "calibrate_lsq"),
    # (class Calibration, 280 lines by this measure, is within the limit: not listed)
    # vision/: the tip tracker, its refinement and template learning
    ("vision/", "refine"),
    ("vision/", "TipTemplate.learn"),
    ("vision/", "TipTracker"),
    # rig/: the rig file's reader came with issue 32 after this test was written; over the limits,
    # left to be split by its owners
    ("rig/", "_Reader"),
    ("rig/", "_Reader.arm"),
}


def _allowed(key: str) -> bool:
    module, name = key.split(":")
    return any(module.startswith(where) and name == qualname for where, qualname in ALLOWED)


def _body_lines(node: ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) -> int:
    """Lines from the first statement after the docstring to the node's last line."""
    body = node.body
    first = body[0]
    if (
        len(body) > 1
        and isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    ):
        first = body[1]
    assert node.end_lineno is not None
    return node.end_lineno - first.lineno + 1


def _measure(tree: ast.AST, prefix: str) -> list[tuple[str, str, int]]:
    """(kind, qualified name, lines) of every function and class below ``tree``."""
    found: list[tuple[str, str, int]] = []
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            name = f"{prefix}{node.name}"
            kind = "class" if isinstance(node, ast.ClassDef) else "function"
            found.append((kind, name, _body_lines(node)))
            found.extend(_measure(node, f"{name}."))
        else:
            found.extend(_measure(node, prefix))
    return found


def measure_package() -> dict[str, tuple[str, int]]:
    """``{"module:qualname": (kind, lines)}`` for every function and class in the package."""
    sizes: dict[str, tuple[str, int]] = {}
    for path in sorted(SRC.rglob("*.py")):
        module = path.relative_to(SRC).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for kind, name, lines in _measure(tree, ""):
            sizes[f"{module}:{name}"] = (kind, lines)
    return sizes


def _too_long(sizes: dict[str, tuple[str, int]]) -> list[str]:
    limit = {"function": MAX_FUNCTION_LINES, "class": MAX_CLASS_LINES}
    return [
        f"{key}: {kind} of {lines} lines (limit {limit[kind]})"
        for key, (kind, lines) in sorted(sizes.items())
        if lines > limit[kind] and not _allowed(key)
    ]


def test_no_function_or_class_over_the_limits() -> None:
    assert _too_long(measure_package()) == []


def test_allow_list_is_not_stale() -> None:
    """Every entry still names something over the limit: a stale one would hide a future long one."""
    limit = {"function": MAX_FUNCTION_LINES, "class": MAX_CLASS_LINES}
    over = [
        (module, name)
        for key, (kind, lines) in measure_package().items()
        if lines > limit[kind]
        for module, name in [key.split(":")]
    ]
    stale = sorted(
        f"{where}{qualname}: within the limits now (or gone): remove it from ALLOWED"
        for where, qualname in ALLOWED
        if not any(m.startswith(where) and n == qualname for m, n in over)
    )
    assert stale == []


def test_the_measure_counts_the_body_not_the_docstring_or_signature() -> None:
    source = (
        "def cmd(\n"
        "    a: int = 1,\n"
        "    b: int = 2,\n"
        ") -> None:\n"
        '    """Doc.\n'
        "\n"
        '    More doc."""\n'
        "    x = a\n"
        "    return None\n"
        "class C:\n"
        '    """Doc."""\n'
        "    def m(self) -> int:\n"
        "        return 1\n"
    )
    sizes = {name: lines for _, name, lines in _measure(ast.parse(source), "")}
    assert sizes == {"cmd": 2, "C": 2, "C.m": 1}


def test_the_check_flags_a_long_function_and_a_long_class() -> None:
    long_body = "".join(f"    x{i} = {i}\n" for i in range(61))
    source = "def f():\n" + long_body + "class K:\n" + "".join(
        f"    y{i} = {i}\n" for i in range(301)
    )
    sizes = {f"m.py:{name}": (kind, lines) for kind, name, lines in _measure(ast.parse(source), "")}
    assert _too_long(sizes) == [
        "m.py:K: class of 301 lines (limit 300)",
        "m.py:f: function of 61 lines (limit 60)",
    ]
