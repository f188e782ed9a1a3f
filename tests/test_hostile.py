"""Issue 34: what a hostile corpus still found, one hypothesis generator per kind.

Each kind of fault has a generator here, written before its fix and failing on the code
before it (the commit that added them marks them ``xfail(strict=True)``; the fixes drop
the marks one kind at a time). Every generator drives the real command line in-process
(typer's ``CliRunner``, or the same ``app`` with a stream of our own where the point is
the stream), with modest example counts: the whole file runs in seconds.

Kinds: a secret in a device URL; user text that holds console markup, terminal control
sequences or bidirectional overrides; blank session labels; an output encoding without
µ; a standard output that fails (a closed pipe, a full device); an output file that
cannot be written; SQLite files that are not ours, damaged, or hold a value of the wrong
type; JSON with a key given twice or a newer version; CSV cells that a spreadsheet would
run; special files (FIFOs, folders, devices); a device that goes silent; options of
infinite size; device URLs that cannot be opened; jog's live display; and messages that
name what was wrong and where instead of Python's own words.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import io
import json
import math
import os
import re
import sqlite3
import stat
import string
import sys
import threading
from pathlib import Path

import pytest
from full_disk import filling_fdopen
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from synth import paper_table  # tests/support, on pytest's pythonpath
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.cli._common import EXIT_CODES

# derandomized in `make test` by the profile (tests/conftest.py); fresh draws with `make test-explore`
HOSTILE = settings(
    max_examples=12,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
FEW = settings(HOSTILE, max_examples=6)

#: Characters that must never reach a terminal raw: C0 controls but the line feed and the tab, DEL, C1 controls,
#: bidirectional marks, embeddings, overrides and isolates, the line and paragraph separators
FORBIDDEN = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069\u2028\u2029]")
#: Python's own words, which tell a user nothing about their input
RAW = (
    "could not convert",
    "float division",
    "division by zero",
    "Expecting ",
    "codec",
    "idna",
    "[Errno",
    "invalid literal",
    "object has no attribute",
    "NoneType",
    "unsupported operand",
    "index out of range",
    "Traceback",
    "UnicodeError",
    "sqlite3.",
    "not enough values to unpack",
    "unhashable",
)


def invoke(args, charset: str = "utf-8", input: str | None = None):
    return CliRunner(charset=charset).invoke(app, [str(a) for a in args], input=input)


def error_line(r, *words: str) -> str:
    """Exit 2, one ``error:`` line (warnings allowed before it), no traceback, no raw Python words; returns it."""
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert r.exit_code == 2, (r.exit_code, r.output)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error:")]
    assert len(errors) == 1 and lines[-1] == errors[0], r.stderr
    starts = [i for i, ln in enumerate(lines) if ln.startswith(("error:", "warning:", "note:"))]
    assert starts and starts[0] == 0, r.stderr  # lines the rich console folded continue the one before
    for raw in RAW:
        assert raw not in errors[0], (raw, errors[0])
    for w in words:
        assert w in errors[0], (w, errors[0])
    return errors[0]


def clean_end(r) -> None:
    """Any documented exit, no traceback, nothing raw for the terminal; an error is one line."""
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert r.exit_code in EXIT_CODES, (r.exit_code, r.output)
    for text in (r.stdout, r.stderr):
        bad = FORBIDDEN.search(text)
        assert bad is None, (repr(bad.group(0)), text)
    if r.exit_code == 2:
        error_line(r)


def visible(text: str) -> str:
    """``text`` as the output rules show it: a character that is not printable as its Python escape."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def squeeze(text: str) -> str:
    return re.sub(r"\s+", "", text)


_counter = iter(range(10**9))


def fresh(tmp_path: Path) -> Path:
    """A new folder for one hypothesis example (the function-scoped tmp_path is shared by all of them)."""
    d = tmp_path / f"ex{next(_counter)}"
    d.mkdir()
    return d


def write_table(path: Path, rows=None, day: str | None = None) -> Path:
    import dataclasses

    from stickslip.measurements import measurements_to_csv

    rows = rows if rows is not None else paper_table()
    if day is not None:
        rows = [dataclasses.replace(t, day=day) for t in rows]
    path.write_text(measurements_to_csv(rows), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def kit(tmp_path_factory):
    """A measurement table, its calibration, a pose table, a filled database and a band tuning (made once)."""
    d = tmp_path_factory.mktemp("kit")
    table = write_table(d / "t.csv")
    cal = d / "cal.json"
    r = invoke(["calibrate", table, "-o", cal])
    assert r.exit_code == 0, r.output
    poses = d / "poses.csv"
    poses.write_text("joint,direction,q1,q2,q3,theta,psi,note\n3,+,0,-1.5707963,0,0,0,a\n2,-,0,0,0.006,0,0,b\n")
    db = d / "s.db"
    assert invoke(["import", table, "-d", "sim://", "--db", db]).exit_code == 0
    assert invoke(["where", "--offline", "--db", db, "--set", "3=min"]).exit_code == 0
    from stickslip.audio.detector import Tuning

    tuning = d / "tuning.json"
    Tuning(band_hz=(5600, 7100), threshold_db=-40.0).save(tuning)
    wav = d / "rec.wav"
    import numpy as np
    import soundfile as sf

    sf.write(wav, np.random.default_rng(0).normal(0, 0.01, 4800).astype("float32"), 48000)
    return {"dir": d, "table": table, "cal": cal, "poses": poses, "db": db, "tuning": tuning, "wav": wav}


def copy_db(kit, to: Path) -> Path:
    """A copy of the kit's database (one consistent file: the source is checkpointed by sqlite's backup)."""
    src = sqlite3.connect(kit["db"])
    dst = sqlite3.connect(to)
    src.backup(dst)
    src.close()
    dst.close()
    return to


def files_under(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


# ---------------------------------------------------------------------------------------------- 1: secrets

secret_words = st.text(alphabet=string.ascii_letters + string.digits, min_size=6, max_size=12).map(
    lambda s: f"Zq{s}7x"
)


@st.composite
def secret_urls(draw):
    s = draw(secret_words)
    scheme = draw(st.sampled_from(["anc300", "mm3a", "mm3a+socket", "sim", "anc300+x", "ftp"]))
    host = draw(st.sampled_from(["10.0.0.2:7230", "lab-pc", "[fe80::1]:7230", "h:99999", ""]))
    form = draw(st.sampled_from(["password", "pw&axes=1,2,3", "userinfo", "token", "both"]))
    if form == "userinfo":
        url = f"{scheme}://admin:{s}@{host}"
    elif form == "both":
        url = f"{scheme}://u:{s}@{host}?timeout=1&password={s}"
    elif form == "token":
        url = f"{scheme}://{host}?token={s}"
    else:
        key, _, rest = form.partition("&")
        url = f"{scheme}://{host}?{key}={s}" + (f"&{rest}" if rest else "")
    return url, s


@HOSTILE
@given(
    case=secret_urls(),
    command=st.sampled_from(["demo", "where", "where-set", "history", "import", "calibrate", "export", "config"]),
    verbose=st.booleans(),
)
@example(case=("anc300://HOST:7230?password=Zqhunter27x", "Zqhunter27x"), command="demo", verbose=False)
def test_a_secret_in_a_device_url_is_never_shown_logged_or_stored(tmp_path, kit, case, command, verbose):
    url, secret = case
    if command == "demo" and url.startswith("sim:"):  # the demo would run (seconds): it refuses any other scheme
        url = "anc300" + url[3:]
    d = fresh(tmp_path)
    db = copy_db(kit, d / "s.db")
    log = d / "debug.log"
    args = {
        "demo": ["demo", "--device", url, "--no-db", "--out", d / "res"],
        "where": ["where", "--offline", "-d", url, "--db", db],
        "where-set": ["where", "--offline", "-d", url, "--db", db, "--set", "3=min"],
        "history": ["history", "-d", url, "--db", db],
        "import": ["import", kit["table"], "--device", url, "--db", db, "--force", "--allow-duplicates"],
        "calibrate": ["calibrate", kit["table"], "--device", url, "-o", d / "cal.json"],
        "export": ["export", "--db", db, "-d", url, "-o", d / "out.csv"],
        "config": ["config", "show", "-d", url],
    }[command]
    r = invoke((["-vv", "--log-file", log] if verbose else []) + args)
    clean_end(r)
    assert secret not in r.stdout and secret not in r.stderr, (r.stdout, r.stderr)
    for name, content in files_under(d).items():
        assert secret.encode() not in content, name


# ------------------------------------------------------------------- 2: user text shown, never interpreted

PIECES = [
    "[/]", "[bold]", "[red]x[/red]", "[link=http://e.x]", ":thumbs_up:", "\x1b[2J", "\x1b]0;title\x07", "\u202e",
    "\u2066", "\x9b31m", "\r", "\x08", "[", "]", "\\", "=1+1", "µ", "\u200f", "\u2028",
]  # fmt: skip
hostile_text = st.lists(
    st.sampled_from(PIECES) | st.text(alphabet=string.ascii_letters + string.digits + " -_.", max_size=4),
    min_size=1,
    max_size=4,
).map("".join)


@HOSTILE
@given(
    text=hostile_text,
    role=st.sampled_from(["table-day", "option-day", "device", "where-device", "path", "out-path"]),
)
@example(text="[/]", role="table-day")
@example(text="\x1b[2J\u202e", role="out-path")
@example(text="a\rb", role="out-path")  # a fresh draw: the wrapping of `saved to` made the \r a space, unseen
def test_user_text_is_shown_not_interpreted(tmp_path, kit, text, role):
    d = fresh(tmp_path)
    db = d / "s.db"
    shown: list[str] = []  # texts that must appear, as the output rules show them, when the command succeeds
    if role == "table-day":
        table = write_table(d / "t.csv", day=text)
        runs = [["import", table, "-d", "sim://", "--db", db], ["history", "--db", db], ["anova", table],
                ["calibrate", table]]
        shown = [text.strip()]
    elif role == "option-day":
        runs = [["calibrate", kit["table"], "--day", text]]
        shown = [text.strip()]
    elif role == "device":
        runs = [["import", kit["table"], "--device", f"sim://?seed={text}", "--db", db], ["history", "--db", db]]
    elif role == "where-device":
        runs = [["where", "--offline", "-d", f"sim://?seed={text}", "--db", db]]
    else:
        name = text.replace("/", "_").replace("\x00", "_")
        if role == "path":
            runs = [["show", d / f"{name}.json"]]
        else:
            runs = [["calibrate", kit["table"], "-o", d / f"{name}.json"]]
            shown = [str(d / f"{name}.json")]
    for args in runs:
        r = invoke(args)
        clean_end(r)
        if r.exit_code == 0 and args is runs[0]:
            for s in shown:
                assert squeeze(visible(s)) in squeeze(r.stdout), (s, r.stdout)


blank = st.text(alphabet=" \t\u00a0\u2003\u3000", max_size=4)


@HOSTILE
@given(label=blank, where=st.sampled_from(["calibrate --day", "fit --day", "traverse --day", "table", "demo --day"]))
@example(label="\t", where="table")  # a fresh draw: written guarded ("'\t"), stripped before unguarded, it read as "'"
def test_a_blank_session_label_is_refused(tmp_path, kit, label, where):
    d = fresh(tmp_path)
    if where == "table":
        r = invoke(["import", write_table(d / "t.csv", day=label), "-d", "sim://", "--db", d / "s.db"])
        error_line(r, "session label")
        assert not (d / "s.db").exists() or "traverses" not in invoke(["history", "--db", d / "s.db", "--json"]).stdout
        return
    cmd = where.split()[0]
    args = {
        "calibrate": ["calibrate", kit["table"], "-o", d / "c.json"],
        "fit": ["fit", kit["table"], "-o", d / "c.json"],
        "traverse": ["traverse", "-j", "3", "--direction", "+", "--tuning", kit["tuning"], "--no-db"],
        "demo": ["demo", "--no-db", "--out", d / "res"],
    }[cmd]
    r = invoke([*args, "--day", label])
    error_line(r, "--day")
    assert not (d / "c.json").exists()


# --------------------------------------------------------------------- 3: an output that cannot encode µ

ENCODED = [
    ["show", "{cal}"],
    ["plan", "-c", "{cal}", "-j", "2", "--from", "0", "--to", "1deg"],
    ["plan", "-c", "{cal}", "-j", "3", "--from", "2mm", "--to", "2.03mm"],
    ["calibrate", "{table}"],
    ["validate", "-c", "{cal}", "{table}"],
    ["anova", "{table}"],
    ["where", "--offline", "--db", "{db}"],
    ["history", "--db", "{db}"],
    ["fit", "{table}"],
    ["move", "-c", "{cal}", "-j", "3", "--by", "20um", "--db", "{db}"],
]
FALLBACK = {"µ": ("um", "urad", "u"), "±": ("+/-",), "°": ("deg",), "—": ("-",), "◀": ("<",)}


@HOSTILE
@given(cmd=st.sampled_from(ENCODED), encoding=st.sampled_from(["ascii", "latin-1", "cp1252", "cp437", "iso8859-7"]))
@example(cmd=ENCODED[0], encoding="ascii")
def test_the_output_degrades_to_what_the_stream_can_encode(tmp_path, kit, cmd, encoding):
    d = fresh(tmp_path)
    files = {**kit, "db": copy_db(kit, d / "s.db")}
    args = [a.format(**{k: str(v) for k, v in files.items()}) for a in cmd]
    if cmd[0] == "move":  # the same move twice: the second from where the first left the joint
        files["db2"] = copy_db(kit, d / "s2.db")
    utf8 = invoke(args if cmd[0] != "move" else [*args[:-1], files["db2"]])
    assert utf8.exit_code == 0, utf8.output
    r = invoke(args, charset=encoding)
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert r.exit_code == 0, r.output
    r.stdout_bytes.decode(encoding)  # strict: it was written in it
    for char, fallbacks in FALLBACK.items():
        try:
            char.encode(encoding)
        except UnicodeEncodeError:
            if char in utf8.stdout:
                assert any(f in r.stdout for f in fallbacks), (char, r.stdout)


def test_data_the_stream_cannot_encode_is_refused_not_changed(tmp_path, kit):
    """CSV on standard output is data: a cell the encoding lacks ends the command (exit 2) instead of being altered."""
    poses = tmp_path / "p.csv"
    poses.write_text("joint,direction,q1,q2,q3,theta,psi,note\n3,+,0,-1.5707963,0,0,0,5 µm\n", encoding="utf-8")
    error_line(invoke(["predict", "-c", kit["cal"], poses], charset="ascii"), "U+00B5 (micro sign)", "-o")
    r = invoke(["predict", "-c", kit["cal"], poses, "--json"], charset="ascii")  # JSON is ASCII: always written
    assert r.exit_code == 0 and json.loads(r.stdout)[0]["note"] == "5 µm"


# ------------------------------------------------------------ 4: a standard output that fails while written


class FailingStream(io.TextIOBase):
    """A standard output that fails (errno) once more than ``limit`` characters were written, and stays failed."""

    def __init__(self, limit: int, code: int) -> None:
        self.limit, self.code, self.n, self.failed, self.text = limit, code, 0, False, []

    @property
    def encoding(self) -> str:
        return "utf-8"

    def _fail(self) -> None:
        self.failed = True
        cls = BrokenPipeError if self.code == errno.EPIPE else OSError
        raise cls(self.code, os.strerror(self.code))

    def write(self, s: str) -> int:
        if self.failed or self.n + len(s) > self.limit:
            self._fail()
        self.n += len(s)
        self.text.append(s)
        return len(s)

    def flush(self) -> None:
        if self.failed:
            self._fail()

    def isatty(self) -> bool:
        return False

    def fileno(self) -> int:
        raise io.UnsupportedOperation("no file descriptor")


def invoke_with_stdout(args, stdout) -> tuple[int, str]:
    """Run the command line with ``stdout`` as the standard output; its exit code and its standard error."""
    err = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="backslashreplace")
    old = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = stdout, err
    try:
        try:
            app([str(a) for a in args], prog_name="stickslip")
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    finally:
        sys.stdout, sys.stderr = old
    err.flush()
    return code, err.buffer.getvalue().decode("utf-8")  # type: ignore[attr-defined]


PRINTING = [
    ["show", "{cal}"],
    ["show", "{cal}", "--json"],
    ["plan", "-c", "{cal}", "-j", "3", "--from", "2mm", "--to", "2.03mm"],
    ["plan", "-c", "{cal}", "-j", "3", "--from", "2mm", "--to", "2.03mm", "--json"],
    ["calibrate", "{table}"],
    ["calibrate", "{table}", "--json"],
    ["predict", "-c", "{cal}", "{poses}"],
    ["history", "--db", "{db}"],
    ["history", "--db", "{db}", "--json"],
    ["fit", "{table}", "--json"],
    ["anova", "{table}"],
    ["config", "show"],
]


@HOSTILE
@given(
    cmd=st.sampled_from(PRINTING),
    code=st.sampled_from([errno.EPIPE, errno.ENOSPC, errno.EIO]),
    limit=st.integers(0, 3000),
)
@example(cmd=PRINTING[0], code=errno.EPIPE, limit=10)
@example(cmd=PRINTING[1], code=errno.ENOSPC, limit=100)
def test_a_standard_output_that_fails_is_an_error_or_a_quiet_end(tmp_path, kit, cmd, code, limit):
    args = [a.format(**{k: str(v) for k, v in kit.items()}) for a in cmd]
    out = FailingStream(limit, code)
    exit_code, err = invoke_with_stdout(args, out)
    if not out.failed:
        assert exit_code == 0, err
        return
    if code == errno.EPIPE:  # the reader went away (| head): quiet, as a Unix tool
        assert exit_code == 1 and err == "", (exit_code, err)
        return
    assert exit_code == 2, (exit_code, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), err
    assert "standard output" in lines[0] and os.strerror(code) in lines[0], lines[0]
    assert not any(raw in lines[0] for raw in RAW), lines[0]


def _cli(*args: object) -> list[str]:
    return [sys.executable, "-c", "from stickslip.cli import main; main()", *map(str, args)]


@pytest.mark.slow  # a subprocess
@pytest.mark.skipif(os.name != "posix", reason="a pipe's reader that goes away (EPIPE) as POSIX has it")
def test_piped_into_head_the_command_ends_quietly(tmp_path, kit):
    """A real pipe whose reader leaves after one line: exit 1, nothing on stderr (no 'Exception ignored')."""
    import subprocess

    poses = tmp_path / "many.csv"
    poses.write_text("joint,direction,q1,q2,q3,theta,psi\n" + "3,+,0,-1.5707963,0,0,0\n" * 50_000)
    p = subprocess.Popen(_cli("predict", "-c", kit["cal"], poses), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout is not None and p.stderr is not None
    first = p.stdout.readline()
    p.stdout.close()  # as head -1 does
    err = p.stderr.read()
    assert p.wait(timeout=120) == 1 and err == b"", err
    assert first.startswith(b"joint,direction")


@pytest.mark.slow  # a subprocess
@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
@pytest.mark.parametrize("json_out", [False, True])
def test_a_full_standard_output_is_one_error_line(kit, json_out):
    import subprocess

    with open("/dev/full", "w") as full:
        r = subprocess.run(
            _cli("show", kit["cal"], *(["--json"] if json_out else [])), stdout=full, stderr=subprocess.PIPE,
            text=True, timeout=120,
        )
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert lines[0] == "error: cannot write to the standard output: No space left on device; the output is incomplete"


# ----------------------------------------------------------------- 5: an output file that cannot be written


@contextlib.contextmanager
def disk_fills_after(limit: int, code: int):
    """Every file opened for writing through ``os.fdopen`` (the atomic writes) fails after ``limit`` characters."""
    real = os.fdopen
    seen = {"n": 0, "failed": False}
    os.fdopen = filling_fdopen(limit, code, seen)
    try:
        yield seen
    finally:
        os.fdopen = real


WRITING = [
    ["calibrate", "{table}", "-o", "{out}"],
    ["fit", "{table}", "-o", "{out}"],
    ["export", "--db", "{db}", "-o", "{out}"],
    ["predict", "-c", "{cal}", "{poses}", "-o", "{out}"],
    ["suggest", "-c", "{cal}", "-o", "{out}"],
]


@HOSTILE
@given(
    cmd=st.sampled_from(WRITING),
    code=st.sampled_from([errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EFBIG]),
    limit=st.integers(0, 4000),
    old=st.sampled_from([None, "the old contents\n"]),
)
@example(cmd=WRITING[0], code=errno.ENOSPC, limit=0, old="the old contents\n")
def test_an_output_file_that_cannot_be_written_keeps_the_old_one(tmp_path, kit, cmd, code, limit, old):
    d = fresh(tmp_path)
    out = d / "out.file"
    if old is not None:
        out.write_text(old)
    args = [a.format(**{k: str(v) for k, v in {**kit, "out": out}.items()}) for a in cmd]
    with disk_fills_after(limit, code) as seen:
        r = invoke(args)
    if not seen["failed"]:
        assert r.exit_code == 0, r.output
        assert seen["n"] > 0  # the file went through the checked, atomic write
        return
    line = error_line(r, str(out), os.strerror(code))
    if old is not None:
        assert out.read_text() == old
        assert "kept" in line, line
    else:
        assert not out.exists()
    assert sorted(p.name for p in d.iterdir()) == (["out.file"] if old is not None else [])


# ------------------------------------------------------------------------- 6: SQLite files that are not ours

OUR_TABLES = ["devices", "sessions", "traverses", "calibrations", "calibration_traverses", "device_state"]


@st.composite
def foreign_schemas(draw):
    names = draw(st.lists(st.sampled_from([*OUR_TABLES, "notes", "users", "t", "photos"]), min_size=0, max_size=4,
                          unique=True))
    app_id = draw(st.sampled_from([0, 0x5374536C + 1, 1, 2**31 - 1, -5]))
    user_version = draw(st.sampled_from([0, 1, 2, 3, 77]))
    if not names and app_id == 0:
        names = ["notes"]  # an empty SQLite file of nobody's may be used; this one holds another's table
    return names, app_id, user_version


COMMANDS_ON_DB = [
    ["history", "--db", "{db}"],
    ["where", "--offline", "--db", "{db}"],
    ["where", "--offline", "--db", "{db}", "--set", "3=min"],
    ["import", "{table}", "-d", "sim://", "--db", "{db}"],
    ["export", "--db", "{db}", "-o", "{out}"],
    ["anova", "--db", "{db}"],
    ["fit", "--db", "{db}"],
    ["exclude", "-t", "1", "-r", "x", "--db", "{db}"],
    ["delete", "-t", "1", "-y", "--db", "{db}"],
    ["move", "-c", "{cal}", "-j", "3", "--by", "1um", "--db", "{db}"],
]


@HOSTILE
@given(schema=foreign_schemas(), cmd=st.sampled_from(COMMANDS_ON_DB))
@example(schema=(["notes"], 0, 0), cmd=COMMANDS_ON_DB[0])
def test_another_applications_sqlite_file_is_refused_untouched(tmp_path, kit, schema, cmd):
    names, app_id, user_version = schema
    d = fresh(tmp_path)
    db = d / "theirs.db"
    con = sqlite3.connect(db)
    for n in names:
        con.execute(f"CREATE TABLE {n} (id INTEGER PRIMARY KEY, x TEXT)")
        con.execute(f"INSERT INTO {n} (x) VALUES ('theirs')")
    con.execute(f"PRAGMA application_id = {app_id}")
    con.execute(f"PRAGMA user_version = {user_version}")
    con.commit()
    con.close()
    before = files_under(d)
    args = [a.format(**{k: str(v) for k, v in {**kit, "db": db, "out": d / "out.csv"}.items()}) for a in cmd]
    r = invoke(args)
    error_line(r, str(db))
    assert files_under(d) == before  # not a byte changed, no journal left, nothing written beside it


@FEW
@given(page=st.integers(0, 100), length=st.sampled_from([4096, 100, 16]), cmd=st.sampled_from(COMMANDS_ON_DB))
@example(page=5, length=4096, cmd=COMMANDS_ON_DB[4])  # the traverses' own page: export read it raw
@example(page=0, length=100, cmd=COMMANDS_ON_DB[0])  # the header
def test_a_damaged_database_is_one_line(tmp_path, kit, page, length, cmd):
    d = fresh(tmp_path)
    db = copy_db(kit, d / "s.db")
    data = bytearray(db.read_bytes())
    at = (page % (len(data) // 4096)) * 4096  # zero (the start of) one of its pages
    data[at : at + length] = bytes(length)
    db.write_bytes(bytes(data))
    args = [a.format(**{k: str(v) for k, v in {**kit, "db": db, "out": d / "out.csv"}.items()}) for a in cmd]
    r = invoke(args)
    clean_end(r)
    if r.exit_code == 2 and "damaged" in r.stderr:
        error_line(r, str(db))


WRONG = {
    "q1": ["'abc'", "X'00ff'", "'1e999'", "9e999"],
    "q2": ["'-pi/2'", "X'01'"],
    "start": ["'x'", "9e999"],
    "steps": ["2.5", "'12000x'", "-3", "0"],
    "joint": ["7", "'x'"],
    "direction": ["'x'", "3"],
}


@HOSTILE
@given(column=st.sampled_from(sorted(WRONG)), data=st.data(), cmd=st.sampled_from(["export", "anova", "fit"]))
@example(column="q1", data=None, cmd="export")
def test_a_stored_value_of_the_wrong_type_is_named(tmp_path, kit, column, data, cmd):
    value = WRONG[column][0] if data is None else data.draw(st.sampled_from(WRONG[column]))
    d = fresh(tmp_path)
    db = copy_db(kit, d / "s.db")
    con = sqlite3.connect(db)
    con.execute("PRAGMA ignore_check_constraints = ON")
    con.execute(f'UPDATE traverses SET "{column}" = {value} WHERE id = 3')
    con.commit()
    con.close()
    out = d / "out.csv"
    args = {"export": ["export", "--db", db, "-o", out], "anova": ["anova", "--db", db], "fit": ["fit", "--db", db]}
    r = invoke(args[cmd])
    error_line(r, str(db), "traverse 3", column)
    assert not out.exists()


# ------------------------------------------------------------ 7: JSON with a key twice, or a newer version


def dumps_pairs(obj) -> str:
    """JSON text of a document read with ``object_pairs_hook=list`` (objects as lists of pairs, keys may repeat)."""
    if isinstance(obj, list) and obj and all(isinstance(p, tuple) and len(p) == 2 for p in obj):
        return "{" + ", ".join(f"{json.dumps(k)}: {dumps_pairs(v)}" for k, v in obj) + "}"
    if isinstance(obj, list):
        return "[" + ", ".join(dumps_pairs(v) for v in obj) + "]"
    return json.dumps(obj)


def objects_in(obj, path=()):
    """Every object (list of pairs) in a pairs document, with its path."""
    if isinstance(obj, list) and obj and all(isinstance(p, tuple) and len(p) == 2 for p in obj):
        yield path, obj
        for k, v in obj:
            yield from objects_in(v, (*path, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from objects_in(v, (*path, i))


@HOSTILE
@given(kind=st.sampled_from(["calibration", "tuning", "state"]), mutation=st.sampled_from(["twice", "newer"]),
       data=st.data())
@example(kind="calibration", mutation="twice", data=None)
def test_json_with_a_key_twice_or_a_newer_version_is_refused(tmp_path, kit, kind, mutation, data):
    d = fresh(tmp_path)
    db = copy_db(kit, d / "s.db")
    if kind == "state":
        con = sqlite3.connect(db)
        text = con.execute("SELECT value FROM device_state WHERE key = 'positions'").fetchone()[0]
        con.close()
    else:
        text = kit["cal" if kind == "calibration" else "tuning"].read_text()
    doc = json.loads(text, object_pairs_hook=list)
    objs = list(objects_in(doc))
    if mutation == "twice":
        _path, obj = objs[0] if data is None else data.draw(st.sampled_from(objs))
        k, v = obj[0] if data is None else data.draw(st.sampled_from(obj))
        obj.append((k, v))
        word = f"'{k}'"
    else:
        newer = 3 if data is None else data.draw(st.integers(3, 10**6))
        top = doc
        top[:] = [(k, v) for k, v in top if k != "version"] + [("version", newer)]
        word = f"version {newer}"
    text = dumps_pairs(doc)
    if kind == "state":
        con = sqlite3.connect(db)
        con.execute("UPDATE device_state SET value = ? WHERE key = 'positions'", (text,))
        con.commit()
        con.close()
        r = invoke(["where", "--offline", "--db", db])
        error_line(r, word, "positions")
        return
    f = d / f"{kind}.json"
    f.write_text(text)
    if kind == "calibration":
        r = invoke(["show", f])
    else:
        r = invoke(["listen", kit["wav"], "--tuning", f])
    error_line(r, str(f), word)


# ------------------------------------------------------------------ 8: CSV cells a spreadsheet would run

TRIGGERS = ("=", "+", "-", "@", "\t", "\r")
formula_labels = st.builds(
    lambda head, tail: head + tail,
    st.sampled_from(["=", "+", "-", "@", "'=", "''+", "-1+"]),
    st.text(alphabet=string.ascii_letters + string.digits + "()!:+-*/ ", min_size=1, max_size=12),
).filter(lambda s: s.strip() == s)


def is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


@FEW
@given(label=formula_labels, q1=st.floats(-math.pi, math.pi, allow_nan=False), note=formula_labels)
@example(label="=HYPERLINK(x)", q1=-0.5, note="@SUM(A1)")
def test_exported_cells_never_start_a_formula_and_numbers_stay_numbers(tmp_path, kit, label, q1, note):
    import dataclasses

    d = fresh(tmp_path)
    rows = [dataclasses.replace(t, day=label, q1=q1 if t.joint != 1 else t.q1) for t in paper_table()]
    table = write_table(d / "t.csv", rows)
    db, out, again = d / "s.db", d / "out.csv", d / "again.csv"
    r = invoke(["import", table, "-d", "sim://", "--db", db])
    if r.exit_code != 0:  # a label the session rules refuse (a date-shaped one): one line, and nothing to export
        error_line(r)
        return
    assert invoke(["export", "--db", db, "-o", out]).exit_code == 0
    cells = [c for row in csv.reader(out.open(newline="")) for c in row]
    for c in cells:  # the rule (docs/cli.md): a plain number, or a lone direction sign, is left as it is
        assert not c.startswith(TRIGGERS) or is_number(c) or c in ("+", "-"), c
    # our own reader takes the guard off: the same labels and numbers come back, the export is a fixed point
    assert invoke(["import", out, "-d", "sim://", "--db", d / "s2.db"]).exit_code == 0
    assert invoke(["export", "--db", d / "s2.db", "-o", again]).exit_code == 0
    assert again.read_text() == out.read_text()
    from stickslip.measurements import read_measurements

    back = read_measurements(out)
    assert {t.day for t in back} == {label} and [t.q1 for t in back] == [t.q1 for t in rows]
    # a pose table's own columns are passed through predict, guarded the same way
    poses = d / "p.csv"
    poses.write_text(f"joint,direction,q1,q2,q3,theta,psi,note\n3,+,{q1!r},-1.5707963,0,0,0,{note}\n")
    r = invoke(["predict", "-c", kit["cal"], poses])
    assert r.exit_code == 0, r.output
    (row,) = list(csv.DictReader(io.StringIO(r.stdout)))
    assert not row["note"].startswith(TRIGGERS) and float(row["q1"]) == q1 and float(row["gamma_pred"]) > 0


# ---------------------------------------------------------------- 9: special files, refused before opening


class FifoWatch:
    """Says whether anyone opened a FIFO, without letting the opener hang.

    For a FIFO that is read (``mode="r"``): a thread keeps trying to open its write end
    without blocking; that succeeds only while a reader is blocked in its open, which the
    thread then releases with an end of file. For one that is written (``mode="w"``): the
    thread holds a read end open from the start (so a writer never blocks), drains it, and
    a writer shows as a pipe that has a writer but no data.
    """

    def __init__(self, path: Path, mode: str) -> None:
        self.path, self.mode, self.opened = path, mode, False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def __enter__(self) -> FifoWatch:
        if self.mode == "w":
            self._rfd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
        self._thread.start()
        return self

    def _watch(self) -> None:
        while not self._stop.wait(0.02):
            if self.mode == "r":
                try:
                    fd = os.open(self.path, os.O_WRONLY | os.O_NONBLOCK)
                except OSError:
                    continue  # ENXIO: nobody reads it (or it is gone)
                self.opened = True
                os.close(fd)
            else:
                try:
                    if os.read(self._rfd, 65536):
                        self.opened = True
                except BlockingIOError:
                    self.opened = True  # a writer holds it open

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        if self.mode == "w":
            os.close(self._rfd)


ROLES = {
    # role: (args with {x} for the special file, "r" read / "w" written)
    "listen": (["listen", "{x}", "--tuning", "{tuning}"], "r"),
    "tune": (["tune", "{x}", "--stop-at", "0.5", "-o", "{out}"], "r"),
    "calibrate": (["calibrate", "{x}"], "r"),
    "import": (["import", "{x}", "-d", "sim://", "--db", "{db}"], "r"),
    "predict": (["predict", "-c", "{cal}", "{x}"], "r"),
    "show": (["show", "{x}"], "r"),
    "tuning": (["listen", "{wav}", "--tuning", "{x}"], "r"),
    "db": (["history", "--db", "{x}"], "r"),
    "log": (["--log-file", "{x}", "config", "path"], "w"),
    "calibrate -o": (["calibrate", "{table}", "-o", "{x}"], "w"),
    "export -o": (["export", "--db", "{db}", "-o", "{x}"], "w"),
    "append": (["traverse", "-j", "3", "--direction", "+", "--tuning", "{tuning}", "--no-db", "-a", "{x}"], "w"),
}


@HOSTILE
@given(role=st.sampled_from(sorted(ROLES)), kind=st.sampled_from(["fifo", "folder", "link-to-fifo", "device"]))
@example(role="listen", kind="fifo")
@example(role="calibrate -o", kind="fifo")
@example(role="import", kind="fifo")  # prov53: file_digest opened it before any check (a hang)
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")
def test_special_files_are_refused_before_they_are_opened(tmp_path, kit, role, kind):
    d = fresh(tmp_path)
    args, mode = ROLES[role]
    fifo = d / "pipe"
    os.mkfifo(fifo)
    if kind == "fifo":
        x = fifo
    elif kind == "folder":
        x = d / "folder"
        x.mkdir()
    elif kind == "link-to-fifo":
        x = d / "link"
        x.symlink_to(fifo)
    else:  # a character device; our own node of /dev/null where we may make one, else the system's for reading
        x = d / "null"
        try:
            os.mknod(x, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        except (PermissionError, AttributeError, OSError):
            if mode == "w":
                return  # never point a write at a system device
            x = Path("/dev/null")
    db = copy_db(kit, d / "s.db")
    before = {p.name: p.lstat().st_mode for p in d.iterdir()}
    full = [a.format(**{k: str(v) for k, v in {**kit, "db": db, "out": d / "o.json", "x": x}.items()}) for a in args]
    with FifoWatch(fifo, mode) as watch:
        r = invoke(full)
    assert not watch.opened, f"{role}: the FIFO was opened"
    error_line(r, str(x))
    assert {p.name: p.lstat().st_mode for p in d.iterdir()} == before  # nothing replaced, nothing new


# ------------------------------------------------------------------ 10: a device that goes silent mid-move


@settings(FEW, max_examples=4)  # timeouts of 0.2 s and more: a loaded machine answers a healthy command late
@given(timeout=st.sampled_from([0.2, 0.3, 0.5]), after=st.integers(0, 2), burst=st.integers(5, 40))
@example(timeout=0.2, after=1, burst=10)
@pytest.mark.slow
def test_a_silent_anc300_ends_within_the_urls_timeout(tmp_path, kit, timeout, after, burst):
    """Everything the driver waits for after the console falls silent stays within the URL's timeout.

    The waits are counted, not timed: each read that ends without an answer adds the
    time it was allowed to wait (its timeout, or the quiet interval of a drain).
    """
    pytest.importorskip("pymeasure")
    from stickslip.devices import transport as tr
    from stickslip.sim.emulators import ANC300Emulator

    d = fresh(tmp_path)
    db = copy_db(kit, d / "s.db")
    waited: list[float] = []
    real_until, real_available = tr.Transport.read_until, tr.Transport.read_available

    def read_until(self, terminators, timeout=None):
        try:
            return real_until(self, terminators, timeout)
        except Exception:
            waited.append(self.timeout if timeout is None else float(timeout))
            raise

    def read_available(self, quiet=0.05, limit=None):
        got = real_available(self, quiet, limit)
        if not got and silent.is_set():
            waited.append(quiet)
        return got

    silent = threading.Event()
    with ANC300Emulator() as emu:
        url = emu.url + f"&delay=0.001&timeout={timeout}"
        assert invoke(["where", "-d", url, "--db", db, "--set", "3=min"]).exit_code == 0
        emu.inject("silent", after=after)
        silent.set()
        tr.Transport.read_until, tr.Transport.read_available = read_until, read_available
        try:
            r = invoke(["move", "-d", url, "-c", kit["cal"], "--db", db, "-j", 3, "--by", "100um",
                        "--burst", burst, "--trust-calibration"])
        finally:
            tr.Transport.read_until, tr.Transport.read_available = real_until, real_available
    error_line(r, "no complete reply")
    burst_s = 1.5 * burst / 1000.0  # the driver's allowance for a burst of this many steps at 1000 Hz
    assert sum(waited) <= timeout + burst_s + 1e-9, (waited, timeout, burst_s)


# ----------------------------------------------------------------------------- 11: options of infinite size


def float_options():
    """(command path, option) of every option of the command line that takes a float."""
    import typer

    def takes_float(p) -> bool:
        descriptor = getattr(p, "type_descriptor", None)  # typer >= 0.25 keeps the annotation here
        if descriptor is not None:
            return descriptor.annotation is float
        return type(p.type).__name__ in ("FloatParamType", "FloatRange")

    found = []

    def walk(cmd, path):
        for name in getattr(cmd, "commands", {}):
            walk(cmd.commands[name], [*path, name])
        for p in cmd.params:
            if p.opts[0].startswith("-") and takes_float(p):
                found.append((tuple(path), p.opts[0]))

    walk(typer.main.get_command(app), [])
    return sorted(found)


FLOAT_OPTIONS = float_options()


@HOSTILE
@given(where=st.sampled_from(FLOAT_OPTIONS), value=st.sampled_from(["1e999", "-1e999", "inf", "-Infinity", "nan"]))
@example(where=(("tune",), "--min-band"), value="1e999")
def test_an_option_of_infinite_size_is_refused_naming_it(tmp_path, where, value):
    path, option = where
    r = invoke([*path, option, value])
    line = error_line(r, option)
    # why: not finite; or the option's range; or, for a length or angle, not a number it can read
    assert any(w in line for w in ("finite", "Input should be", "cannot read")), line


def test_the_float_options_are_found():
    assert ((("tune",), "--min-band") in FLOAT_OPTIONS and (("calibrate",), "--frequency") in FLOAT_OPTIONS
            and len(FLOAT_OPTIONS) >= 8), FLOAT_OPTIONS


# ------------------------------------------------------------------ 12: device URLs that cannot be opened

unopenable = st.one_of(
    st.sampled_from([
        "anc300://[::1", "http://example.com", "mm3a", "/dev/ttyUSB0", "anc300://h:99999", "anc300://",
        "anc300://" + "a" * 64 + ".lab:7230", "anc300://" + ".".join(["abcdefgh"] * 30), "sim:", "://",
        "mm3a://", "anc300://h:-1", "anc300://h:x",
    ]),
    st.builds(lambda s: f"{s}://h", st.sampled_from(["faulty", "x", "sim+y", "mm3a+telnet"])),
)  # fmt: skip


@HOSTILE
@given(url=unopenable, cmd=st.sampled_from(["import", "calibrate", "fit"]))
@example(url="anc300://[::1", cmd="import")
def test_a_device_url_that_cannot_be_opened_is_never_stored(tmp_path, kit, url, cmd):
    d = fresh(tmp_path)
    db = d / "s.db"
    args = {
        "import": ["import", kit["table"], "--device", url, "--db", db],
        "calibrate": ["calibrate", kit["table"], "--device", url, "-o", d / "c.json"],
        "fit": ["fit", kit["table"], "--device", url, "--record", "--db", db],
    }[cmd]
    r = invoke(args)
    error_line(r, "--device")
    assert not (d / "c.json").exists()
    if db.exists():
        con = sqlite3.connect(db)
        assert con.execute("SELECT COUNT(*) FROM devices").fetchone()[0] == 0
        con.close()


# -------------------------------------------------------------------------- 13: jog's live display


class Terminal:
    """A small terminal: the screen a stream of text and ANSI cursor movement leaves (independent of rich).

    It wraps at ``width`` columns, scrolls at the bottom of ``height`` rows, and understands
    the sequences a live display uses: CR, LF, cursor up/down/previous line, erase line,
    SGR (ignored) and cursor show/hide (ignored). ``scrolled`` counts lines pushed off the top.
    """

    def __init__(self, width: int, height: int = 40) -> None:
        self.width, self.height = width, height
        self.rows = [""] * height
        self.row = self.col = 0
        self.scrolled = 0

    def _newline(self) -> None:
        self.row += 1
        if self.row == self.height:
            self.rows = self.rows[1:] + [""]
            self.row -= 1
            self.scrolled += 1

    def feed(self, text: str) -> None:
        i = 0
        while i < len(text):
            c = text[i]
            if c == "\x1b":
                m = re.match(r"\x1b\[([0-9;?]*)([A-Za-z])", text[i:])
                assert m, repr(text[i : i + 10])
                n = int(m.group(1)) if m.group(1).isdigit() else 1
                kind = m.group(2)
                if kind == "A":
                    self.row = max(0, self.row - n)
                elif kind == "B":
                    self.row = min(self.height - 1, self.row + n)
                elif kind == "F":
                    self.row, self.col = max(0, self.row - n), 0
                elif kind == "K":
                    self.rows[self.row] = ""
                elif kind == "G":
                    self.col = n - 1
                i += len(m.group(0))
                continue
            if c == "\r":
                self.col = 0
            elif c == "\n":
                self.col = 0
                self._newline()
            else:
                if self.col >= self.width:
                    self.col = 0
                    self._newline()
                line = self.rows[self.row].ljust(self.col)
                self.rows[self.row] = line[: self.col] + c + line[self.col + 1 :]
                self.col += 1
            i += 1


class TtyStream(io.StringIO):
    def isatty(self) -> bool:
        return True


jog_status = st.builds(
    lambda q, tip, lim, speed, rates, single, image, angle, sent, message: __import__(
        "stickslip.procedures.jog", fromlist=["JogStatus"]
    ).JogStatus(q, tip, lim, speed, (0.0, 0.0, 0.0), rates, single, image, angle, sent, message),
    st.tuples(st.floats(-4, 4), st.floats(-4, 1), st.floats(0, 0.012)),
    st.tuples(*[st.floats(-0.05, 0.05)] * 3),
    st.tuples(st.floats(0, 4), st.floats(0, 4), st.floats(0, 0.012)),
    st.sampled_from([1e-7, 3e-7, 1e-6, 3e-6, 1e-5, 3e-5, 1e-4]),
    st.tuples(*[st.floats(-20000, 20000)] * 3),
    st.booleans(),
    st.booleans(),
    st.floats(-math.pi, math.pi),
    st.lists(st.integers(-(10**9), 10**9), min_size=3, max_size=3),
    st.text(alphabet=string.ascii_letters + " .,;:()-", max_size=200),
)


@FEW
@given(statuses=st.lists(jog_status, min_size=2, max_size=4), width=st.sampled_from([80, 100, 120]))
def test_jogs_display_fits_and_redraws_in_place(monkeypatch, statuses, width):
    from stickslip.cli import taskspace

    out = TtyStream()
    monkeypatch.setenv("COLUMNS", str(width))
    monkeypatch.setenv("LINES", "40")
    monkeypatch.setattr(sys, "stdout", out)
    screen = taskspace._Screen()
    term = Terminal(width)
    heights = []
    for s in statuses:
        screen.show(s)
        term.feed(out.getvalue())
        out.seek(0)
        out.truncate()
        heights.append(max(i for i, row in enumerate(term.rows) if row.strip()) + 1)  # rows down to the last used
    getattr(screen, "close", lambda: None)()
    term.feed(out.getvalue())
    assert term.scrolled == 0, "the display scrolled: it printed new lines instead of redrawing"
    for row in term.rows:
        assert len(row.rstrip()) <= width
    assert len(set(heights)) == 1, heights  # every frame the same height: each logical line on one row
    assert any("q: quit" in row for row in term.rows), term.rows


# ------------------------------------------------------------------------ 14: messages that help


@HOSTILE
@given(
    case=st.sampled_from(
        [
            (["where", "--offline", "--db", "{db}", "--q2", "pi/0"], ["--q2", "pi/0", "zero"]),
            (["plan", "-c", "{cal}", "-j", "3", "--from", "0", "--to", "1um", "--q1", "-pi/0"], ["--q1", "zero"]),
            (["plan", "-c", "{cal}", "-j", "3", "--from", "0", "--to", "1e999"], ["--to", "finite"]),
            (["traverse", "-j", "3", "--direction", "+", "--tuning", "{tuning}", "--no-db", "--psi", "x"],
             ["--psi", "x"]),
            (["move", "-c", "{cal}", "-j", "2", "--by", "pi/0", "--db", "{db}"], ["--by", "zero"]),
            (["where", "-d", "anc300://" + "a" * 64 + ".lab:7230", "--db", "{db}"], ["--device", "host name"]),
            (["where", "-d", "anc300://" + ".".join(["abcdefgh"] * 30), "--db", "{db}"], ["--device", "host name"]),
            (["show", "{badjson}"], ["{badjson}", "line 1", "column"]),
            (["listen", "{wav}", "--tuning", "{badjson}"], ["{badjson}", "line 1", "column"]),
            (["calibrate", "{badcsv}"], ["{badcsv}:2", "q2"]),
            (["predict", "-c", "{cal}", "{badposes}"], ["{badposes}:2", "q2"]),
        ]
    )
)
def test_messages_name_what_was_wrong_and_where(tmp_path, kit, case):
    d = fresh(tmp_path)
    files = {**kit, "db": copy_db(kit, d / "s.db"), "badjson": d / "b.json", "badcsv": d / "b.csv",
             "badposes": d / "p.csv"}
    files["badjson"].write_text('{"format": "stickslip-calibration", x}')
    files["badcsv"].write_text(kit["table"].read_text().replace("\n2026", "\n2026", 1).replace(",-1.5707", ",abc", 1))
    files["badposes"].write_text("joint,direction,q1,q2,q3,theta,psi\n3,+,0,abc,0,0,0\n")
    args, words = case
    fill = {k: str(v) for k, v in files.items()}
    r = invoke([a.format(**fill) for a in args])
    error_line(r, *[w.format(**fill) for w in words])


# ------------------------------------------------------------------------ the rules themselves


def test_the_output_and_file_rules_hold_their_examples():
    import doctest

    from stickslip import records
    from stickslip.cli import _output

    assert doctest.testmod(records).failed == 0 and doctest.testmod(_output).failed == 0


@settings(HOSTILE, max_examples=200)
@given(cell=st.text(alphabet="=+-@'\t\r0123456789.eE aZ(", max_size=8) | formula_labels)
def test_guarding_a_cell_is_reversible_and_leaves_no_formula(cell):
    from stickslip.records import guard_cell, unguard_cell

    out = guard_cell(cell)
    assert unguard_cell(out) == cell
    assert not out.startswith(TRIGGERS) or is_number(out) or out in ("+", "-")
    assert out == cell or out == "'" + cell  # at most one quote added, nothing else changed


@settings(HOSTILE, max_examples=200)
@given(text=st.text(max_size=30), encoding=st.sampled_from(["utf-8", "ascii", "latin-1", "cp437"]))
def test_visible_text_is_safe_for_the_terminal_and_the_stream(text, encoding):
    from stickslip.cli._output import visible

    out = visible(text, encoding)
    assert FORBIDDEN.search(out) is None
    out.encode(encoding)  # never a UnicodeEncodeError
    assert visible(out, encoding) == out  # shown once, as it stays


def test_a_calibration_number_beyond_a_float_is_one_error_line(tmp_path):
    """Found by tests/test_fuzz_files.py: a 341-digit integer in a calibration file ended in an OverflowError."""
    from test_reach import true_calibration

    p = tmp_path / "cal.json"
    true_calibration().save(p)
    doc = json.loads(p.read_text())
    doc["parameters"][0]["value"] = 10**340
    p.write_text(json.dumps(doc))
    r = CliRunner().invoke(app, ["move", "-c", str(p), "-j", "3", "--by", "1um", "--db", str(tmp_path / "s.db")])
    assert r.exit_code == 2 and r.exception is None or isinstance(r.exception, SystemExit)
    assert r.stderr.strip() == (f"error: {p}: parameters[0] (joint 1 gamma0) must be a finite number, "
                                "got an integer beyond ±1.8e308")


def test_a_table_with_bare_carriage_returns_is_refused_in_the_users_words(tmp_path):
    """Found by tests/test_fuzz_files.py: Python's "open the file in universal-newline mode" reached the user."""
    p = tmp_path / "mac.csv"
    p.write_bytes(b"day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\r2026-11-20,3,+,0,-1.5,0,0,0,0,0.004,4000\r")
    for args in (["import", str(p), "-d", "sim://", "--db", str(tmp_path / "s.db")],
                 ["calibrate", str(p), "-o", str(tmp_path / "c.json")]):
        r = CliRunner().invoke(app, args)
        assert r.exit_code == 2 and r.stderr.strip() == (
            f"error: {p}: not a readable CSV table (a line ends in a bare carriage return (CR, an old Mac export): "
            "save the table with LF or CRLF ends)"), r.stderr


@pytest.mark.parametrize(("digits", "words"), [(340, "frame must be in 1..10000000, got a number beyond 1e30"),
                                               (5000, "a whole number of 5001 characters: no field takes one so long")])
def test_a_tuning_with_a_whole_number_beyond_a_float_is_one_error_line(tmp_path, digits, words):
    """Found by tests/test_fuzz_files.py: math.isfinite(10**340) raised OverflowError; 5000 digits hit Python's
    4300-digit limit, whose words (sys.set_int_max_str_digits) reached the user."""
    tuning = tmp_path / "t.json"
    tuning.write_text('{"frame": 1' + "0" * (digits) + "}")
    wav = tmp_path / "a.wav"
    wav.write_bytes(b"")
    r = CliRunner().invoke(app, ["listen", str(wav), "--tuning", str(tuning)])
    assert r.exit_code == 2 and r.stderr.strip() == f"error: {tuning}: {words}", r.stderr
