"""The history store against damaged files and values written by hand, through the command line.

A copy of a filled database is truncated at any length, or has bytes overwritten anywhere
(its schema text included), then every command that reads or writes the store is run on
it: each ends in a documented exit, and a refusal is one ``error:`` line (no traceback, no
Python words). Kept positions written by hand (a non-number, a number outside the joint's
range) are refused naming the entry, or taken as uncertain, never used as known.
"""

from __future__ import annotations

import json
import random
import sqlite3

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import test_hostile
from stickslip.storage import Store, StoreError
from test_hostile import COMMANDS_ON_DB, HOSTILE, clean_end, copy_db, error_line, fresh, invoke

kit = test_hostile.kit  # the fixture: a measurement table, its calibration and a filled database (made once)


def _args(kit, cmd, db, d):
    return [a.format(**{k: str(v) for k, v in {**kit, "db": db, "out": d / "out.csv"}.items()}) for a in cmd]


@pytest.mark.slow
@settings(HOSTILE, max_examples=15)
@given(seed=st.integers(0, 2**32 - 1), how=st.sampled_from(["truncate", "byte", "bytes"]),
       cmd=st.sampled_from(COMMANDS_ON_DB))
def test_a_truncated_or_overwritten_store_is_one_line_or_works(tmp_path, kit, seed, how, cmd):
    rng = random.Random(seed)
    d = fresh(tmp_path)
    db = copy_db(kit, d / "s.db")
    data = bytearray(db.read_bytes())
    if how == "truncate":
        data = data[: rng.randrange(1, len(data))]
    else:
        for _ in range(1 if how == "byte" else rng.randint(2, 30)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    db.write_bytes(bytes(data))
    clean_end(invoke(_args(kit, cmd, db, d)))


def test_a_schema_whose_text_is_not_utf8_is_refused_naming_the_file(tmp_path, kit):
    db = copy_db(kit, tmp_path / "s.db")
    data = bytearray(db.read_bytes())
    at = data.index(b"tablecalibrations") + len(b"tablecalibratio")  # a table's name in sqlite_master
    data[at] = 0xC7  # a lead byte followed by no continuation byte: SQLite's message quoting it cannot be decoded
    db.write_bytes(bytes(data))
    with pytest.raises(StoreError) as e:  # was a UnicodeDecodeError ("'utf-8' codec can't decode byte 0xc7")
        Store.open(db)
    assert str(db) in str(e.value) and "damaged" in str(e.value) and "not UTF-8" in str(e.value)
    error_line(invoke(["history", "--db", db]), str(db), "damaged")


def _with_position(kit, d, joint: str, text: str):
    db = copy_db(kit, d / "s.db")
    con = sqlite3.connect(db)
    rowid, value = con.execute("SELECT rowid, value FROM device_state WHERE key = 'positions'").fetchone()
    state = json.loads(value)
    state["positions"][joint] = "@"
    con.execute("UPDATE device_state SET value = ? WHERE rowid = ?", (json.dumps(state).replace('"@"', text), rowid))
    con.commit()
    con.close()
    return db


@pytest.mark.parametrize("text", ["null", '"x"', "[]", "true", "1e999"])
def test_a_kept_position_that_is_no_number_is_named(tmp_path, kit, text):
    db = _with_position(kit, tmp_path, "2", text)
    for cmd in (["where", "--offline", "--db", db], ["move", "-c", kit["cal"], "-j", "2", "--by", "1mrad", "--db", db]):
        line = error_line(invoke(cmd), "stored positions", "q2")  # was "float() argument must be ..."
        assert "not a" in line


@pytest.mark.parametrize("text", ["-5.0", "1e308", "0.6"])
def test_a_kept_position_outside_its_joints_range_is_uncertain_not_shown_as_known(tmp_path, kit, text):
    db = _with_position(kit, tmp_path, "2", text)
    r = invoke(["where", "--offline", "--db", db])
    assert r.exit_code == 0, r.output
    line = next(ln for ln in r.stdout.splitlines() if "joint 2" in ln)
    assert "uncertain, between -210 deg and 30 deg" in line, r.stdout  # was "-286.479 deg (default)", "inf deg"
    assert "inf" not in r.stdout and "286" not in r.stdout
    moved = invoke(["move", "-c", kit["cal"], "-j", "2", "--to", "-100deg", "--db", db])
    error_line(moved, "joint 2's position is uncertain")


# -- a full disk at any point of a sequence of writes ------------------------------------------------------------


def _filled(tmp_path, rows):
    db = tmp_path / "full.db"
    with Store.open(db) as st:
        st.add_traverses(rows, device="sim://", how="imported")
        st.set_state("sim://", "note", {"kept": 0})
    return db


@pytest.mark.slow
@settings(HOSTILE, max_examples=12)
@given(room=st.integers(0, 12), writes=st.lists(st.sampled_from(["one", "many", "state", "big state"]), min_size=1,
                                                 max_size=6))
def test_a_write_that_finds_the_disk_full_never_loses_what_was_there(tmp_path, monkeypatch, room, writes):
    """The file may grow by ``room`` pages (SQLite's ``max_page_count``: "database or disk is full") while ``writes``
    run: each is stored whole or refused in one line; the rows and state stored before stay, the file checks ok."""
    from synth import paper_table

    import stickslip.storage.sqlite as backend

    rows = paper_table()
    db = _filled(fresh(tmp_path), rows)
    opened = backend._connect

    def tight(path):
        con = opened(path)
        pages = con.execute("PRAGMA page_count").fetchone()[0]
        con.execute(f"PRAGMA max_page_count = {pages + room}")
        return con

    expect_rows, expect_state = len(rows), {"kept": 0}
    with monkeypatch.context() as m:
        m.setattr(backend, "_connect", tight)
        with Store.open(db) as store:
            for i, what in enumerate(writes):
                value = {"kept": i + 1, "pad": "x" * (20000 if what == "big state" else 10)}
                try:
                    if what == "one":
                        store.add_traverse(rows[i % len(rows)], device="sim://")
                    elif what == "many":
                        store.add_traverses(rows * 3, device="sim://", how="imported")
                    else:
                        store.set_state("sim://", "note", value)
                except StoreError as e:
                    text = str(e)
                    assert "\n" not in text and str(db) in text and "nothing of this change was stored" in text, text
                    continue
                expect_rows += {"one": 1, "many": 3 * len(rows)}.get(what, 0)
                expect_state = value if "state" in what else expect_state
    with Store.open(db) as store:
        assert store.integrity_check() == "ok"
        assert store.count_traverses() == expect_rows
        assert store.get_state("sim://", "note") == expect_state
