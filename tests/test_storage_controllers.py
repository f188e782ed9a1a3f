"""One controller, one device, one kept position (schema 5), however its URL is written.

Before schema 5 a device's rows were stored under its URL's key (``anc300://h``, ``anc300://h:7230`` and
``anc300://h/`` were three devices, each with kept positions of its own) while its lock was its controller's:
a move through one spelling left the others where the arm no longer was. Now ``storage.schema.stored_device`` is
the controller's name (``devices.base.controller_of``) and the upgrade from 4 renames and merges the spellings;
positions they kept apart become uncertain over the joint's whole range (``storage.spellings``).
"""

from __future__ import annotations

import json
import sqlite3

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from synth import paper_table
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.devices.positions import DeviceState, load_state
from stickslip.joints import JOINTS, coordinate_bound
from stickslip.storage import SCHEMA_VERSION, Store
from stickslip.storage.schema import content_key, lock_name, stored_device
from stickslip.storage.spellings import merge_positions

ROWS = paper_table()
OLD, NEW = "2026-11-30T10:00:00+00:00", "2026-11-30T11:00:00+00:00"
HOLDER = {"pid": 4242, "host": "bench-pc", "since": "2026-11-30T09:00:00"}


def _positions(q3: float, source: str, claim: list[float], theta: float, q1: float = 0.25) -> str:
    s = DeviceState.default("x")
    s.positions[1], s.sources[1] = q1, "set"
    s.positions[3], s.sources[3] = q3, source
    s.claim[3] = (claim[0], claim[1])
    s.theta = theta
    return json.dumps(s.to_json())


SPELLINGS = {  # as the schema-4 code stored them: three names of one ANC300, and another device
    "anc300://h": (ROWS[:3], {"positions": (_positions(0.001, "set", [0.001, 0.002], 0.1), OLD),
                              "lock": (json.dumps(HOLDER), OLD), "controller": ('{"identity": "x"}', OLD),
                              "named": ('{"park": [0, 0, 0]}', OLD)}),
    "anc300://h:7230": (ROWS[2:5], {"positions": (_positions(0.002, "dead-reckoned", [0.002, 0.003], 0.2), NEW),
                                    "lock": ("null", NEW), "controller": ('{"identity": "x"}', NEW),
                                    "named": ('{"rest": [0, 0, 0]}', NEW)}),
    "anc300://h/": (ROWS[5:6], {}),
    "sim://": (ROWS[6:7], {"positions": (_positions(0.003, "set", [0.0, 0.0], 0.0), OLD)}),
}


def _schema_4_store(db) -> list[int]:
    """A store as schema 4 wrote it, made through the store's own connection (on PostgreSQL too); traverse ids."""
    ids = []
    with Store.open(db) as st, st._write() as con:
        for url, (rows, state) in SPELLINGS.items():
            did = con.insert("INSERT INTO devices (url, created_at) VALUES (?, 'x')", (url,))
            for t in rows:
                sid = st._session_id(con, did, t.day)
                ids.append(st._insert_row(con, t, sid, "old", "x", None, content_key(t, url)))
            for key, (value, at) in state.items():
                con.execute("INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, ?, ?, ?)",
                            (did, key, value, at))
        con.set_schema_version(4)
    return ids


def test_the_upgrade_to_5_makes_the_spellings_one_device_and_never_keeps_a_disagreeing_position(db):
    ids = _schema_4_store(db)
    with Store.open(db) as st:
        assert st.upgraded_from == 4 and st.schema_version == SCHEMA_VERSION == 5
        assert [d["url"] for d in st.devices()] == ["anc300://h:7230", "sim://"]
        notes = st.upgrade_notes
        assert notes[0] == ("the devices anc300://h and anc300://h:7230 are one device now, anc300://h:7230 "
                            "(docs/storage.md): the 3 traverse(s) and 0 calibration(s) of anc300://h moved to it, "
                            "none deleted")
        assert notes[1].startswith("anc300://h:7230: the positions kept under anc300://h and anc300://h:7230 "
                                   "disagree on joint(s) 3: neither can be trusted"), notes[1]
        assert "joint(s) 3 are uncertain over their whole range until referenced again" in notes[1]
        assert notes[2].startswith("anc300://h:7230: the base tilt kept under the two spellings differs: the one "
                                   "written last is kept (theta = 0.2 rad"), notes[2]
        assert notes[3].startswith("the devices anc300://h/ and anc300://h:7230 are one device now")
        assert notes[4].startswith(f"1 traverse(s) of anc300://h:7230 were stored under two spellings as well "
                                   f"(the same day, pose and steps), kept: ids {ids[3]} "), notes[4]
        assert len(notes) == 5
        for spelling in ("anc300://h", "anc300://H:7230/", "anc300://h/?password=x"):
            assert st.count_traverses(spelling) == 7, spelling  # nothing deleted: 3 + 3 + 1
        state = load_state(st, "anc300://h/")
        assert state.uncertain == {3: (JOINTS[3].lower, JOINTS[3].upper)}  # kept apart: its whole range
        assert "anc300://h and anc300://h:7230, one controller, kept two positions of it" in state.why[3]
        assert state.positions[1] == 0.25 and state.referenced(1) and state.referenced(2) is False
        assert state.claim == {3: (0.001, 0.003)}  # the span both claims cover
        assert state.theta == 0.2  # the tilt written last
        kept = {k: st.get_state("anc300://h:7230", k) for k in (
            "lock", "lock (from anc300://h:7230)", "controller", "controller (from anc300://h)", "named",
            "named (from anc300://h)", "positions (from anc300://h)", "positions (from anc300://h:7230)")}
        assert kept["lock"] == HOLDER and kept["lock (from anc300://h:7230)"] is None  # a holder over none
        assert kept["controller"] == {"identity": "x"} and kept["controller (from anc300://h)"] is None  # the same
        assert kept["named"] == {"rest": [0, 0, 0]} and kept["named (from anc300://h)"] == {"park": [0, 0, 0]}
        assert kept["positions (from anc300://h)"]["positions"]["3"] == 0.001  # each as it was kept, beside
        assert kept["positions (from anc300://h:7230)"]["positions"]["3"] == 0.002
        assert load_state(st, "sim://").positions[3] == 0.003 and not load_state(st, "sim://").uncertain
        assert st.duplicates(ROWS[:6], "anc300://h:7230/") == list(range(6))
        assert st.integrity_check() == "ok"


def test_the_upgrade_note_is_said_and_where_shows_the_joint_uncertain(tmp_path):
    db = tmp_path / "lab.db"
    _schema_4_store(db)
    r = CliRunner().invoke(app, ["where", "-d", "anc300://h", "--db", str(db), "--offline", "--json"])
    assert r.exit_code == 0, r.output
    said = " ".join(r.stderr.split())
    assert "note: upgraded the database" in said and "from schema version 4 to 5" in said
    assert "disagree on joint(s) 3: neither can be trusted" in said
    assert (tmp_path / "lab.v4.db").exists()
    w = json.loads(r.stdout)
    assert w["device"] == "anc300://h:7230" and "also_kept" not in w
    assert w["joints"][2]["source"] == "uncertain" and w["joints"][2]["uncertain"] == [0.0, 0.012]
    con = sqlite3.connect(tmp_path / "lab.v4.db")  # the copy is the store as it was
    try:
        assert con.execute("PRAGMA user_version").fetchone()[0] == 4
        assert con.execute("SELECT COUNT(*) FROM devices").fetchone()[0] == 4
    finally:
        con.close()


def test_agreeing_positions_are_kept_and_an_unreadable_one_leaves_every_joint_uncertain():
    a = json.loads(_positions(0.001, "set", [0.001, 0.001], 0.1))
    merged, apart = merge_positions(a, json.loads(json.dumps(a)), False, "why")
    assert apart == [] and merged == {**a, "claim": {"3": [0.001, 0.001]}}
    merged, apart = merge_positions(a, {}, False, "why")  # the other could not be read
    assert apart == [1, 2, 3] and merged["uncertain"]["2"] == [JOINTS[2].lower, JOINTS[2].upper]
    merged, apart = merge_positions(a, {**a, "positions": {**a["positions"], "3": 0.002}}, True, "why")
    assert apart == [3] and merged["uncertain"]["3"] == [-coordinate_bound(3), coordinate_bound(3)]  # a rig arm's


def test_a_lock_row_that_cannot_be_read_is_kept_where_unlock_finds_it(tmp_path):
    db = tmp_path / "lab.db"
    with Store.open(db) as st, st._write() as con:
        for url, lock in (("anc300://h", "null"), ("anc300://h/", "not json{")):
            did = con.insert("INSERT INTO devices (url, created_at) VALUES (?, 'x')", (url,))
            con.execute("INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, 'lock', ?, ?)",
                        (did, lock, OLD))
        con.set_schema_version(4)
    r = CliRunner().invoke(app, ["where", "-d", "anc300://h", "--db", str(db), "--offline", "--unlock"])
    assert r.exit_code == 0, r.output
    with Store.open(db) as st:
        assert st.get_state("anc300://h", "lock") is None and st.acquire_lock("anc300://h", HOLDER) is None


def test_positions_of_two_spellings_neither_the_name_are_kept_beside_under_their_own_names(tmp_path):
    db = tmp_path / "lab.db"
    with Store.open(db) as st, st._write() as con:
        for url, q3 in (("anc300://h", 0.001), ("anc300://h/", 0.004), ("anc300://H", 0.004)):
            did = con.insert("INSERT INTO devices (url, created_at) VALUES (?, 'x')", (url,))
            con.execute("INSERT INTO device_state (device_id, key, value, updated_at) VALUES (?, 'positions', ?, ?)",
                        (did, _positions(q3, "set", [q3, q3], 0.0), OLD))
        con.set_schema_version(4)
    with Store.open(db) as st:
        assert [d["url"] for d in st.devices()] == ["anc300://h:7230"]
        said = [n for n in st.upgrade_notes if "disagree" in n]
        assert len(said) == 2 and said[1].startswith("anc300://h:7230: the positions kept under anc300://H and ")
        assert said[:1] == [
            "anc300://h:7230: the positions kept under anc300://h/ and anc300://h disagree on joint(s) 3: neither "
            "can be trusted (a move through one spelling planned from the other's old position), so joint(s) 3 are "
            "uncertain over their whole range until referenced again (`stickslip where -d anc300://h:7230 --set "
            "J=Q`); each spelling's positions are kept beside, under 'positions (from ...)'"]
        assert st.get_state("anc300://h", "positions (from anc300://h)")["positions"]["3"] == 0.001
        assert st.get_state("anc300://h", "positions (from anc300://h/)")["positions"]["3"] == 0.004
        assert st.get_state("anc300://h", "positions (from anc300://H)")["positions"]["3"] == 0.004
        state = load_state(st, "anc300://h")
        assert state.uncertain == {3: (0.0, 0.012)} and state.claim == {3: (0.001, 0.004)}


# ---------------------------------------------------------------- one name per controller

_HOSTS = st.sampled_from(["h", "lab-nano", "10.0.0.2", "[fe80::1]", "anc-2.lab"])


@st.composite
def _spelling(draw, host: str, differ: str = "") -> str:
    """One way of writing ``anc300://host`` (its default port 7230): case, the port written or not, a trailing
    slash, options, a user and password. ``differ``: another port (``:7231``) or a path (``/x``): another
    controller."""
    h = "".join(c.upper() if draw(st.booleans()) else c for c in host)
    user = draw(st.sampled_from(["", "admin@", "admin:s3cret@", "u:p%40ss@"]))
    port = differ if differ.startswith(":") else draw(st.sampled_from(["", ":7230", ":07230"]))
    slash = differ if differ.startswith("/") else draw(st.sampled_from(["", "/"]))
    opts = draw(st.sampled_from(["", "?password=123456", "?timeout=5&password=x", "?timeout=2"]))
    return f"{draw(st.sampled_from(['anc300', 'ANC300']))}://{user}{h}{port}{slash}{opts}"


@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.data(), _HOSTS)
def test_every_spelling_of_one_controller_has_one_stored_name(data, host):
    a, b = data.draw(_spelling(host)), data.draw(_spelling(host))
    name = stored_device(a)
    assert name == stored_device(b) == lock_name(a) == lock_name(b) == stored_device(name), (a, b)
    assert name == f"anc300://{host.lower()}:7230"
    assert "s3cret" not in name and "p%40ss" not in name and "?" not in name and "@" not in name


@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.data(), _HOSTS, _HOSTS, st.sampled_from(["", ":7231", "/x"]))
def test_two_controllers_never_share_a_stored_name(data, host, other_host, differ):
    assume(host != other_host or differ)
    a, b = data.draw(_spelling(host)), data.draw(_spelling(other_host, differ))
    assert stored_device(a) != stored_device(b) and lock_name(a) != lock_name(b), (a, b)


@pytest.mark.parametrize(("a", "b"), [
    ("anc300://h", "smaract-mcs2://h"),  # another scheme: another controller (even at one address)
    ("anc300://h", "anc300://h:7231"),
    ("anc300://h#arm=left", "anc300://h#arm=right"),  # two arms of one controller: a state each
    ("anc300://h#arm=left", "anc300://h"),
    ("sim://?seed=1", "sim://?seed=2"),
    ("mm3a:///dev/ttyUSB0", "mm3a:///dev/ttyUSB1"),
    ("rig://stop/Bench", "rig://stop/bench"),
])
def test_two_devices_keep_two_names(a, b):
    assert stored_device(a) != stored_device(b)


def test_a_rig_arm_of_a_spelled_controller_is_one_arm():
    assert stored_device("anc300://H/#arm=left") == stored_device("anc300://h:7230#arm=left") == (
        "anc300://h:7230#arm=left")
