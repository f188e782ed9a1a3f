"""Round trips of the history: what goes out of a store (export, backup) and comes back in is the same, and is known.

A table exported from one store and imported into another (docs/storage.md: a rig's file moved into the lab's
PostgreSQL), or into the same one again, keeps every value and its rows are recognised as already stored.
"""

from __future__ import annotations

import datetime as dt
import itertools
import json
import math
import re
import struct
from dataclasses import replace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.clock import day_label_problem
from stickslip.joints import MAX_STROKE, JointSpec
from stickslip.measurements import Traverse, measurements_to_csv, parse_measurements
from stickslip.storage import Store
from stickslip.storage.schema import _content_keys


def _rows() -> list[Traverse]:
    # np.round(-1e-9, 6) and -1 * 0.0 are -0.0: a table written by numpy or pandas holds negative zeros
    return [
        Traverse("2026-11-20", 3, "+", -0.0, -1.0, 0.0, -0.0, 0.0, -0.0, 0.01, 10),
        Traverse("2026-11-20", 1, "-", 0.0, -0.5, 0.004, 0.0, -0.0, 0.3, -0.0, 1234),
    ]


def test_an_exported_table_with_negative_zeros_is_known_as_stored(db):
    """SQLite stores -0.0 as 0: the export writes 0.0, and its rows must have the keys they were stored with."""
    rows = _rows()
    with Store.open(db) as st:
        st.add_traverses(rows, device="sim://", how="imported")
        exported = parse_measurements(measurements_to_csv(st.iter_traverses()))
        assert exported == rows  # equal as numbers (-0.0 == 0.0)
        assert st.duplicates(exported, "sim://") == [0, 1]
        assert st.duplicates(rows, "sim://") == [0, 1]
        assert st.device_holding(exported) is not None


def test_a_row_stored_with_the_signed_zero_key_of_before_is_still_found(db):
    rows = _rows()
    with Store.open(db) as st:
        (tid, _) = st.add_traverses(rows, device="sim://")
        signed = _content_keys(rows[:1], "sim://", signed_zeros=True)[0]
        with st._write() as con:  # the key a row with -0.0 was stored with before zeros were unsigned
            con.execute("UPDATE traverses SET content = ? WHERE id = ?", (signed, tid))
        assert st.duplicates(rows, "sim://") == [0, 1]
        assert signed != _content_keys(rows[:1], "sim://")[0]
        assert math.copysign(1.0, rows[0].q1) < 0


def _row(**kw: object) -> Traverse:
    values: dict[str, object] = dict(
        day="2026-11-20", joint=3, direction="+", q1=0.0, q2=-1.0, q3=0.0, theta=0.0, psi=0.0, start=0.0, end=0.01,
        steps=10,
    )
    values.update(kw)
    return Traverse(**values)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "bad, why",
    [
        (_row(day="a\nb"), "control character"),
        (_row(day="2026-13-45"), "starts like a date but is not one"),
        (_row(day="22.11.2026"), "22.11.2026"),
        (_row(theta=9.0), "theta = 9 rad is outside"),
        (_row(psi=-4.0), "psi = -4 rad is outside"),
        (_row(start=0.01), "a traverse must move"),
        (_row(direction="-"), "direction '-' disagrees"),
        (_row(steps=2.5), "steps must be a whole number"),  # was stored as 2
        (_row(steps=10**12 + 1), "steps must be a whole number"),
        (_row(end=math.inf), "end must be a finite number"),  # was stored, then every read of the device refused
    ],
)
def test_the_store_refuses_a_traverse_its_export_could_not_import_again(db, bad, why):
    with Store.open(db) as st:
        with pytest.raises(ValueError, match=re.escape(why)):
            st.add_traverse(bad)
        with pytest.raises(ValueError, match=re.escape(why)):
            st.add_traverses([_row(), bad])
        assert st.count_traverses() == 0 and st.days() == []


def test_a_label_with_spaces_around_is_stored_as_the_table_reads_it(db):
    """The table's reader strips a label: the store does too, so an exported row comes back in its session."""
    with Store.open(db) as st:
        st.add_traverse(_row(day=" day1 "))
        st.add_traverses([_row(day="day1\u3000", steps=11)])  # an ideographic space is stripped too
        assert st.days() == ["day1"]
        assert [t.day for t in parse_measurements(measurements_to_csv(st.iter_traverses()))] == ["day1", "day1"]


_ANY = JointSpec(1, "rotary", -math.inf, math.inf, "rad")
"""A joint without stops: the store does not know the arm, and these rows are of any arm."""
_examples = itertools.count()
_finite = st.floats(-MAX_STROKE, MAX_STROKE, width=64)  # a position of any arm's joint (a metre is within a turn)
_edges = st.sampled_from([5e-324, -5e-324, MAX_STROKE, -MAX_STROKE, -0.0, 0.0, 0.1, 1 / 3, 2.2250738585072014e-308])
_labels = st.text(st.characters(codec="utf-8"), min_size=1, max_size=20).filter(lambda s: day_label_problem(s) is None)


@st.composite
def _traverses(draw: st.DrawFn) -> Traverse:
    start, end = sorted(draw(st.lists(st.one_of(_edges, _finite), min_size=2, max_size=2, unique=True)))
    direction = draw(st.sampled_from("+-"))
    if direction == "-":
        start, end = end, start
    tilt = st.one_of(st.sampled_from([-0.0, 5e-324, 0.1, math.pi, -math.pi]), st.floats(-math.pi, math.pi))
    return Traverse(
        draw(_labels), draw(st.sampled_from([1, 2, 3])), direction, draw(st.one_of(_edges, _finite)),
        draw(st.one_of(_edges, _finite)), draw(st.one_of(_edges, _finite)), draw(tilt), draw(tilt), start, end,
        draw(st.integers(1, 10**12)),
    )


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(_traverses(), min_size=1, max_size=5))
def test_what_the_store_keeps_is_what_its_export_reads_back_bit_for_bit(db, rows):
    """Stored, exported, read: every float the same double (bar a zero's sign on SQLite), and the rows known."""
    device = f"sim://?seed={next(_examples) + 1}"  # a device (a simulated arm) per example: one database for all
    with Store.open(db) as st:
        st.add_traverses(rows, device=device)
        text = measurements_to_csv(st.iter_traverses(device=device))
        back = parse_measurements(text, joints={j: _ANY for j in (1, 2, 3)})
        assert st.duplicates(back, device) == list(range(len(rows)))
    assert measurements_to_csv(back) == text  # out, in, out: the same bytes
    for a, b in zip(rows, back, strict=True):
        assert a.day.strip() == b.day
        for name in ("q1", "q2", "q3", "theta", "psi", "start", "end"):
            assert struct.pack("<d", getattr(a, name) + 0.0) == struct.pack("<d", getattr(b, name) + 0.0), name


def test_a_stored_calibration_is_shown_as_the_file_it_was_saved_as(db, tmp_path):
    """`show N -o` writes the bytes `calibrate -o` wrote: the nested records (an update's prior, a family
    selection) keep their order; stored sorted, they came back reordered (the same JSON, another file)."""
    from synth import paper_table

    from stickslip.calibration import Calibration, calibrate
    from stickslip.calibration.update import update_calibration

    rows = paper_table()
    cal, _ = update_calibration(calibrate(rows), rows[:4])
    assert list(cal.to_dict()["provenance"]["prior"]) == ["day", "method", "created"]  # not in sorted order
    cal.save(tmp_path / "made.json")
    with Store.open(db) as st:
        ids = st.add_traverses(rows, device="sim://")
        cid = st.add_calibration(cal, "sim://", ids)
        st.calibration(cid).save(tmp_path / "shown.json")
    assert (tmp_path / "shown.json").read_bytes() == (tmp_path / "made.json").read_bytes()
    assert Calibration.load(tmp_path / "shown.json").to_dict() == cal.to_dict()


def test_a_history_moved_from_its_file_to_postgresql_and_back_is_the_same_table(tmp_path, postgres_url):
    """docs/storage.md's move (export from the file, import into the lab's database), then back: the same bytes
    out at every step, and the table taken back is known as stored (not imported twice)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    rows = [*_rows(), _row(day="2026-11-21 pm", q1=0.1, q2=-1 / 3, start=5e-324, end=1.2e-2, steps=10**12),
            _row(day="Tag 2 – Überprüfung", direction="-", start=0.012, end=2.2250738585072014e-308, theta=-math.pi)]
    run = CliRunner().invoke
    lite, first, second, third = tmp_path / "rig.db", tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    with Store.open(lite) as st:
        st.add_traverses(rows, device="mm3a:///dev/ttyUSB0", how="audio")
    dev = ["-d", "mm3a:///dev/ttyUSB0"]
    assert run(app, ["export", "--db", str(lite), *dev, "-o", str(first)]).exit_code == 0
    r = run(app, ["import", str(first), "--db", postgres_url, *dev])
    assert r.exit_code == 0, r.output
    assert run(app, ["export", "--db", postgres_url, *dev, "-o", str(second)]).exit_code == 0
    assert second.read_bytes() == first.read_bytes()
    with Store.open(postgres_url) as pg:
        assert pg.traverses() == rows
    r = run(app, ["import", str(second), "--db", str(lite), *dev])  # back home: every row is there already
    assert r.exit_code == 2 and f"{len(rows)} of {len(rows)} rows are already stored" in r.stderr, r.output
    assert run(app, ["export", "--db", str(lite), *dev, "-o", str(third)]).exit_code == 0
    assert third.read_bytes() == first.read_bytes()


def test_a_device_state_its_reader_would_refuse_is_not_stored_and_the_old_one_is_kept(db, tmp_path):
    """A NaN in a kept track was stored, and every later read of the device's positions refused it."""
    from stickslip.devices.positions import DeviceState, JsonStateFile, load_state, save_state

    good = DeviceState.default("sim://")
    good.set_position(3, -0.0)
    good.set_position(1, 5e-324)
    good.set_position(2, -1 / 3)
    bad = DeviceState.default("sim://")
    bad.track[3] = {"P": [[0.0, 0.0], [0.0, math.nan]]}
    with Store.open(db) as st:
        save_state(st, good)
        with pytest.raises(ValueError, match="NaN/Infinity"):
            save_state(st, bad)
        with pytest.raises(ValueError, match="NaN/Infinity"):
            st.set_state("sim://", "journal", '{"q": Infinity}')
        back = load_state(st, "sim://")
        assert back == good and math.copysign(1.0, back.positions[3]) < 0  # bit for bit, the sign of 0 too
        save_state(st, back)
        assert st.get_state("sim://", "positions") == good.to_json()
    f = JsonStateFile(tmp_path / "state.json")
    save_state(f, good)
    before = (tmp_path / "state.json").read_bytes()
    with pytest.raises(ValueError, match=r"track.3.P.1.1 is nan: NaN/Infinity"):
        save_state(f, bad)
    assert (tmp_path / "state.json").read_bytes() == before and load_state(f, "sim://") == good


def test_a_file_or_stored_calibration_its_reader_would_refuse_is_not_written(db, tmp_path):
    """json.dumps writes NaN and Infinity, which every reader refuses: a calibration with an infinite covariance
    replaced the good file with one `-c` refused, and stored, made latest_calibration fail for the device."""
    import numpy as np
    from synth import paper_table

    from stickslip.calibration import Calibration, calibrate

    good = calibrate(paper_table())
    good.save(tmp_path / "cal.json")
    before = (tmp_path / "cal.json").read_bytes()
    bad = calibrate(paper_table())
    bad.covariance[(3, "+")] = np.full((3, 3), np.inf)
    with pytest.raises(ValueError, match=r"covariance.0.0 is inf: NaN/Infinity .* nothing written"):
        bad.save(tmp_path / "cal.json")
    assert (tmp_path / "cal.json").read_bytes() == before and Calibration.load(tmp_path / "cal.json")
    with Store.open(db) as st:
        cid = st.add_calibration(good, "sim://")
        with pytest.raises(ValueError, match="NaN/Infinity"):
            st.add_calibration(bad, "sim://")
        assert st.latest_calibration("sim://").to_dict() == good.to_dict() and len(st.calibrations()) == 1
        assert st.calibrations()[0]["id"] == cid


def test_a_camera_or_tuning_file_its_reader_would_refuse_is_not_written(tmp_path):
    from stickslip import kinematics as kin
    from stickslip.audio.tuning import tune
    from stickslip.audio.tuningfile import Tuning
    from stickslip.sim.sound import render_traverse_recording
    from stickslip.vision.jacobian import MeasuredDirection, MeasuredJacobian

    pose = kin.Pose(0.0, -0.5, 0.001, 0.0, 0.0)
    ok = MeasuredDirection(3, "+", (1.0, 0.0), 0.01, 0.1, 40, 1e-6)
    huge = MeasuredDirection(3, "-", (1.7e308, 0.0), 0.01, 0.1, 40, 1e-6)  # px per m = 1.7e314: inf
    MeasuredJacobian("sim-camera://", 1e-6, pose, (10.0, 20.0), (ok,), "2026-11-20").save(tmp_path / "j.json")
    before = (tmp_path / "j.json").read_bytes()
    with pytest.raises(ValueError, match="directions.1.px_per_unit.0 is -inf"):
        MeasuredJacobian("sim-camera://", 1e-6, pose, (10.0, 20.0), (ok, huge), "2026-11-20").save(tmp_path / "j.json")
    assert (tmp_path / "j.json").read_bytes() == before
    assert MeasuredJacobian.load(tmp_path / "j.json").to_dict()["directions"][0]["px_per_unit"] == [1e6, 0.0]

    x, sr = render_traverse_recording(3, 1000.0, 2.0, 3.5, seed=11)
    tuning = tune(x, sr, 2.0, joint=3)
    tuning.save(tmp_path / "t.json")
    before = (tmp_path / "t.json").read_bytes()
    assert Tuning.load(tmp_path / "t.json").save(tmp_path / "t2.json") and (tmp_path / "t2.json").read_bytes() == before
    with pytest.raises(ValueError, match="threshold_db nan must be within"):  # refused when made: never written
        replace(tuning, threshold_db=math.nan)


def test_a_backup_answers_every_query_as_the_database_it_was_taken_from(db, tmp_path):
    """`stickslip backup` of either backend: the same rows (floats at the edges, labels in any script), the same
    exclusions and their reasons, calibrations, kept state; the copy's export reads back as the original's."""
    from synth import paper_table

    from stickslip.calibration import calibrate
    from stickslip.devices.positions import DeviceState, load_state, save_state

    rows = [*_rows(), _row(day="Tag 2 – Überprüfung", q2=-1 / 3, start=5e-324, end=MAX_STROKE, steps=10**12),
            _row(day="日本 2", direction="-", start=0.1, end=2.2250738585072014e-308, theta=-math.pi)]
    state = DeviceState.default("mm3a://com3")
    state.set_position(3, 0.005)
    state.mark_uncertain(2, -1.0, -0.5, "a move was interrupted – Ctrl-C")
    with Store.open(db) as st:
        ids = st.add_traverses(rows, device="mm3a://com3", how="audio", source="sha256:abc")
        st.set_excluded(ids[-1:], "der Arm berührte die Probe \u2013 'x'")
        cid = st.add_calibration(calibrate(paper_table()), "mm3a://com3", ids[:2])
        save_state(st, state)
        want = (st.history(), st.traverse_records(), st.calibrations(), st.days(), st.calibration_traverses(cid),
                st.calibration(cid).to_dict(), load_state(st, "mm3a://com3"), st.has_source("sha256:abc"))
        text = measurements_to_csv(st.iter_traverses())
        st.backup(tmp_path / "copy.db")
    with Store.open(tmp_path / "copy.db") as copy:
        got = (copy.history(), copy.traverse_records(), copy.calibrations(), copy.days(),
               copy.calibration_traverses(cid), copy.calibration(cid).to_dict(), load_state(copy, "mm3a://com3"),
               copy.has_source("sha256:abc"))
        assert got == want
        anyarm = {j: _ANY for j in (1, 2, 3)}
        assert parse_measurements(measurements_to_csv(copy.iter_traverses()), joints=anyarm) == parse_measurements(
            text, joints=anyarm
        )
        assert copy.duplicates(rows, "mm3a://com3") == list(range(len(rows)))


# ---------------------------------------------------------------- a moved history is the same record (prov53)

_TEXT = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), min_size=1, max_size=30)
"""Free text kept with a row: commas, quotes, line breaks, any script (PostgreSQL's text holds no NUL)."""


def _history_of(db: object) -> tuple[object, list[tuple[Traverse, object]]]:
    """``history --json`` of a database, and every traverse (excluded ones too) with its provenance."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    r = CliRunner().invoke(app, ["history", "--db", str(db), "--json"])
    assert r.exit_code == 0, r.output
    with Store.open(db) as s:
        return json.loads(r.stdout), list(s.iter_provenance())  # parsed: by_joint's order is the engine's collation


def test_a_history_moved_with_export_json_is_the_same_record(db, tmp_path):
    """Measured, imported and excluded rows, exported with --json and imported into an empty database: the same
    history (its measurement times, not the import's) and every row's how, source, time and exclusion."""
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import read_measurements

    run = CliRunner().invoke
    home, moved, table = tmp_path / "rig.db", tmp_path / "rig.jsonl", tmp_path / "rig.csv"
    with Store.open(home) as s:
        s.add_traverse(_row(steps=11), "mm3a://com3", how="audio", measured_at=dt.datetime(2026, 11, 20, 9, 30,
                                                                                         tzinfo=dt.UTC))
        s.add_traverse(_row(steps=12, direction="-", start=0.01, end=0.0), "mm3a://com3", how="camera",
                       measured_at=dt.datetime(2026, 11, 20, 17, 5, 1, 250, tzinfo=dt.UTC))
        ids = s.add_traverses([_row(day="2026-11-21", steps=13), _row(day="2026-11-21", steps=14)], "mm3a://com3",
                              how="imported", source='lab "B", run 2\nÜberprüfung')
        s.set_excluded([ids[1]], 'cable snagged, "twice"\nsee log')
    dev = ["-d", "mm3a:///COM3"]
    r = run(app, ["export", "--db", str(home), *dev, "--json", "-o", str(moved)])
    assert r.exit_code == 0 and "wrote 4 traverses with their provenance" in r.output, r.output
    r = run(app, ["import", str(moved), "--db", str(db), *dev])
    assert r.exit_code == 0 and "imported 4 traverses" in r.output, r.output
    before, after = _history_of(home), _history_of(db)
    assert after == before
    assert [(p.how, p.excluded) for _, p in after[1]] == [
        ("audio", None), ("camera", None), ("imported", None), ("imported", 'cable snagged, "twice"\nsee log')]
    assert after[0][0]["first_measured_at"] == "2026-11-20T09:30:00.000000+00:00"  # not the import's time
    assert after[0][0]["last_measured_at"] == "2026-11-20T17:05:01.000250+00:00"
    assert after[0][1]["excluded"] == 1 and after[0][1]["traverse_ids"] == [3, 4]
    # the CSV table is the contract's, unchanged: the used rows, the header exactly
    assert run(app, ["export", "--db", str(db), *dev, "-o", str(table)]).exit_code == 0
    assert table.read_text().splitlines()[0] == "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps"
    assert [t.steps for t in read_measurements(table)] == [11, 12, 13]
    r = run(app, ["import", str(moved), "--db", str(db), *dev])  # again: every row is there already
    assert r.exit_code == 2 and "4 of 4 rows are already stored" in r.stderr, r.output


def test_a_history_file_with_a_bad_time_is_refused_with_its_row_and_value(db, tmp_path):
    from typer.testing import CliRunner

    from stickslip.cli import app

    head = '{"format": "stickslip-history", "version": 1}\n'
    row = ('{"day": "d1", "joint": 3, "direction": "+", "q1": 0, "q2": -1, "q3": 0, "theta": 0, "psi": 0, '
           '"start": 0, "end": 0.01, "steps": %d, "how": "audio", "measured_at": %s}\n')
    bad = tmp_path / "h.jsonl"
    bad.write_text(head + row % (10, '"2026-11-20T09:30:00+00:00"') + row % (11, '"2026-13-01T00:00:00+00:00"')
                   + row % (12, '"2026-11-20T09:30:00"') + row % (13, "1764000000"))
    run = CliRunner().invoke
    r = run(app, ["import", str(bad), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2, r.output
    assert f'{bad}:3: measured_at "2026-13-01T00:00:00+00:00": not an ISO 8601 date and time' in r.stderr
    assert f'{bad}:4: measured_at "2026-11-20T09:30:00": has no UTC offset' in r.stderr
    assert f"{bad}:5: measured_at 1764000000: must be text" in r.stderr
    assert f"{bad}:2:" not in r.stderr
    r = run(app, ["import", str(bad), "-d", "sim://", "--db", str(db), "--how", "audio"])
    assert r.exit_code == 2 and "history file: its rows keep their own 'how'" in r.stderr
    # the fields left out mean what they mean for a table's row: imported, now, used
    bad.write_text(head + row.replace(', "how": "audio", "measured_at": %s', "") % 10)
    r = run(app, ["import", str(bad), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 0, r.output
    with Store.open(db) as s:
        ((_, p),) = list(s.iter_provenance())
        assert (p.how, p.source, p.excluded) == ("imported", None, None) and p.measured_at[:4] == "2026"


def test_a_history_time_outside_the_years_1_to_9999_in_utc_is_refused_with_its_row(tmp_path):
    """A time whose offset takes it before year 1 or past 9999 in UTC was an OverflowError traceback (audit56)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    row = ('{"day": "d1", "joint": 3, "direction": "+", "q1": 0, "q2": -1, "q3": 0, "theta": 0, "psi": 0, '
           '"start": 0, "end": 0.01, "steps": %d, "measured_at": "%s"}\n')
    bad = tmp_path / "h.jsonl"
    bad.write_text('{"format": "stickslip-history", "version": 1}\n' + row % (10, "0001-01-01T00:00:00+01:00")
                   + row % (11, "9999-12-31T23:59:59-01:00") + row % (12, "9999-12-31T23:59:59+00:00"))
    db = tmp_path / "s.db"
    r = CliRunner().invoke(app, ["import", str(bad), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2, r.output
    assert f'{bad}:2: measured_at "0001-01-01T00:00:00+01:00": is outside the years 1 to 9999' in r.stderr
    assert f'{bad}:3: measured_at "9999-12-31T23:59:59-01:00": is outside the years 1 to 9999' in r.stderr
    assert f"{bad}:4:" not in r.stderr and "Traceback" not in r.output
    with Store.open(db) as s:
        assert s.count_traverses() == 0


def test_a_history_line_giving_a_field_twice_is_refused_not_read_as_its_last(tmp_path):
    """json keeps the last of two equal keys: q1 0.0 then 0.5 was stored as 0.5 without a word (audit56)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    row = ('{"day": "d1", "joint": 3, "direction": "+", "q1": 0.0, "q2": -1, "q3": 0, "theta": 0, "psi": 0, '
           '"start": 0, "end": 0.01, "steps": 10%s}\n')
    h = tmp_path / "h.jsonl"
    h.write_text('{"format": "stickslip-history", "version": 1}\n' + row % "" + row % ', "q1": 0.5'
                 + row % ', "how": "audio", "how": "camera"')
    db = tmp_path / "s.db"
    r = CliRunner().invoke(app, ["import", str(h), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2, r.output
    assert f"{h}:3: field 'q1' given twice (0.0 and 0.5): keep one" in r.stderr, r.stderr
    assert f"""{h}:4: field 'how' given twice ("audio" and "camera"): keep one""" in r.stderr, r.stderr
    assert f"{h}:2:" not in r.stderr
    with Store.open(db) as s:
        assert s.count_traverses() == 0


def test_a_history_text_no_store_can_keep_is_refused_with_its_line_on_both_backends(db, tmp_path):
    """A NUL in a source was stored by SQLite but refused by PostgreSQL ('the database refused the value: ...
    cannot contain NUL'), and a lone surrogate escape (\\ud800) was "error: 'utf-8' codec can't encode character",
    neither naming the file or line (audit56)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    row = {"day": "d1", "joint": 3, "direction": "+", "q1": 0, "q2": -1, "q3": 0, "theta": 0, "psi": 0,
           "start": 0, "end": 0.01, "steps": 10}
    h = tmp_path / "h.jsonl"
    h.write_text("\n".join([json.dumps({"format": "stickslip-history", "version": 1}),
                            json.dumps({**row, "source": "lab \"B\"\nrun 2"}),  # line breaks and quotes are kept
                            json.dumps({**row, "steps": 11, "source": "x\x00y"}),
                            json.dumps({**row, "steps": 12, "excluded": "r\ud800"}),
                            json.dumps({**row, "steps": 13, "how": "\udc80"})]) + "\n")
    r = CliRunner().invoke(app, ["import", str(h), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2, r.output
    assert r.stderr.strip().removeprefix("error: ").split("; ") == [
        f"{h}:3: source holds a NUL character (\\u0000), which a PostgreSQL store cannot keep: remove it",
        f"{h}:4: excluded holds \\ud800, half of a UTF-16 pair and no character (not UTF-8): write the character "
        "itself, or its pair",
        f"{h}:5: how holds \\udc80, half of a UTF-16 pair and no character (not UTF-8): write the character itself, "
        "or its pair",
    ], r.stderr
    with Store.open(db) as s:
        assert s.count_traverses() == 0


def test_a_history_file_with_empty_lines_above_its_format_line_is_refused_saying_so(tmp_path):
    """import took it for a history file (its first character past the blanks is '{') and then said 'not a stickslip
    history file (line 1 must be ...)' of a file whose line 3 was that very line (audit56)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    h = tmp_path / "h.jsonl"
    h.write_text('\n \n{"format": "stickslip-history", "version": 1}\n{"day": "d1", "joint": 3, "direction": "+", '
                 '"q1": 0, "q2": -1, "q3": 0, "theta": 0, "psi": 0, "start": 0, "end": 0.01, "steps": 10}\n')
    r = CliRunner().invoke(app, ["import", str(h), "-d", "sim://", "--db", str(tmp_path / "s.db")])
    assert r.exit_code == 2, r.output
    assert r.stderr.strip() == (f'error: {h}:1: line 1 is empty: a history file\'s first line is {{"format": '
                                '"stickslip-history", "version": 2} (delete the empty lines above it)'), r.stderr


def test_a_table_whose_first_cell_starts_with_a_brace_is_refused_naming_both_formats(tmp_path):
    """import reads a file starting with '{' as a history file; a CSV whose first cell is '{id}' was told only 'not
    a stickslip history file (line 1 must be {"format": ...})', as if it had been meant as one (audit56)."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    t = tmp_path / "m.csv"
    t.write_text("{id},day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n1,d1,3,+,0,-1,0,0,0,0,0.01,10\n")
    r = CliRunner().invoke(app, ["import", str(t), "-d", "sim://", "--db", str(tmp_path / "s.db")])
    assert r.exit_code == 2, r.output
    assert r.stderr.strip() == (
        f'error: {t}:1: neither a stickslip history file (line 1 must be {{"format": "stickslip-history", '
        "\"version\": 2}) nor a table (its first character is '{'; a table's line 1 is its header "
        "day,joint,direction,q1,q2,q3,theta,psi,start,end,steps)"), r.stderr


@pytest.mark.parametrize("command", ["calibrate", "fit", "anova"])
def test_a_history_file_given_where_a_table_is_read_says_what_it_is_and_what_to_do(tmp_path, command):
    """The table readers said 'header must be exactly day,... (missing day, ..., unexpected {"format": ...})'
    for export --json's file (audit56): one line naming it and the two ways on."""
    from typer.testing import CliRunner

    from stickslip.cli import app

    h = tmp_path / "h.jsonl"
    h.write_text('{"format": "stickslip-history", "version": 1}\n{"day": "d1", "joint": 3, "direction": "+", '
                 '"q1": 0, "q2": -1, "q3": 0, "theta": 0, "psi": 0, "start": 0, "end": 0.01, "steps": 10}\n')
    r = CliRunner().invoke(app, [command, str(h)])
    assert r.exit_code == 2, r.output
    assert r.stderr.strip().splitlines() == [
        f"error: {h}:1: a stickslip history file (export --json), not a table: import it (stickslip import {h} "
        "-d URL) and read the store (--db, no table), or write a table (stickslip export -o TABLE.csv)"
    ], r.stderr


def test_a_history_file_given_as_poses_to_predict_says_what_it_is_and_what_to_do(tmp_path):
    """predict said 'header lacks joint, q1, ...' for export --json's file (audit56)."""
    from synth import paper_table
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import write_measurements

    write_measurements(tmp_path / "m.csv", paper_table())
    cal = tmp_path / "cal.json"
    run = CliRunner().invoke
    assert run(app, ["calibrate", str(tmp_path / "m.csv"), "-o", str(cal)]).exit_code == 0
    h = tmp_path / "h.jsonl"
    h.write_text('{"format": "stickslip-history", "version": 1}\n{"day": "d1", "joint": 3, "direction": "+", '
                 '"q1": 0, "q2": -1, "q3": 0, "theta": 0, "psi": 0, "start": 0, "end": 0.01, "steps": 10}\n')
    r = run(app, ["predict", str(h), "--calibration", str(cal)])
    assert r.exit_code == 2, r.output
    assert r.stderr.strip().splitlines() == [
        f"error: {h}:1: a stickslip history file (export --json), not a pose table: write its rows as a table "
        "(stickslip export -o TABLE.csv) and give that"
    ], r.stderr


@st.composite
def _provenances(draw: st.DrawFn) -> object:
    from stickslip.measurements.history_file import Provenance

    when = draw(st.datetimes(timezones=st.just(dt.UTC)))
    return Provenance(draw(_TEXT.filter(str.strip)), when.isoformat(timespec="microseconds"),
                      draw(st.none() | _TEXT), draw(st.none() | _TEXT.filter(str.strip)))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.tuples(_traverses(), _provenances()), min_size=1, max_size=4))
def test_any_provenance_text_survives_the_move(db, tmp_path, rows):
    """Any text in how, source and a reason (commas, quotes, line breaks, any script), any time: stored, written
    as a history file, read, stored again: the same rows and provenance, as the store keeps them."""
    from stickslip.measurements.history_file import read_history, write_history

    n = next(_examples) + 1
    with Store.open(db) as s:
        s.add_with_provenance(rows, device=f"sim://?seed={n}")
        kept = list(s.iter_provenance(device=f"sim://?seed={n}"))
        write_history(tmp_path / f"{n}.jsonl", kept)
        back = [r for batch in read_history(tmp_path / f"{n}.jsonl", {j: _ANY for j in (1, 2, 3)}) for r in batch]
        assert back == kept
        assert {p.device for _, p in back} == {f"sim://?seed={n}"}  # each row says whose it is
        with pytest.raises(ValueError, match=f"a row names the device sim://\\?seed={n}, not "):
            s.add_with_provenance(back, device=f"sim://?seed={n + 10**6}")  # never silently under another arm
        other = [(t, replace(p, device=f"sim://?seed={n + 10**6}")) for t, p in back]  # another arm: no duplicate
        s.add_with_provenance(other)
        assert list(s.iter_provenance(device=f"sim://?seed={n + 10**6}")) == other
    for (t, p), (u, q) in zip(rows, kept, strict=True):
        assert (u.steps, u.direction, q.measured_at) == (t.steps, t.direction, p.measured_at)


def _cli(*args):
    from typer.testing import CliRunner

    from stickslip.cli import app

    return CliRunner().invoke(app, [str(a) for a in args])


def test_a_history_of_two_devices_goes_back_to_each_and_never_under_one(tmp_path):
    """A store of two arms exported whole (export --json) used to lose whose each row was: imported with -d
    sim://, both arms' rows became sim://'s, and a calibration of sim:// mixed two arms' step sizes. Each row
    now names its device; the import stores it there, or refuses a --device the rows contradict (nothing
    stored), and a version-1 file (no device) still needs --device."""
    from synth import paper_table

    from stickslip.measurements import write_measurements

    rows = paper_table()
    write_measurements(tmp_path / "a.csv", rows[:5])
    write_measurements(tmp_path / "b.csv", rows[5:9])
    one, two, three = (tmp_path / f"{n}.db" for n in ("one", "two", "three"))
    assert _cli("import", tmp_path / "a.csv", "-d", "anc300://h:7230?password=x", "--db", one).exit_code == 0
    assert _cli("import", tmp_path / "b.csv", "-d", "mm3a:///COM3", "--db", one).exit_code == 0
    h = tmp_path / "all.jsonl"
    assert _cli("export", "--json", "--db", one, "-o", h).exit_code == 0
    lines = h.read_text(encoding="utf-8").splitlines()
    assert json.loads(lines[0]) == {"format": "stickslip-history", "version": 2}
    assert [json.loads(x)["device"] for x in lines[1:]] == ["anc300://h:7230"] * 5 + ["mm3a://com3"] * 4

    r = _cli("import", h, "--db", three, "-d", "sim://")
    assert r.exit_code == 2 and " ".join(r.stderr.split()) == (
        f"error: {h}: rows 2-6: the file names the device anc300://h:7230, not sim:// (--device): leave --device "
        f"out to store each row under the device it names; {h}: rows 7-10: the file names the device mm3a://com3, "
        "not sim:// (--device): leave --device out to store each row under the device it names"), r.stderr
    with Store.open(three) as s:
        assert s.count_traverses() == 0  # nothing stored

    r = _cli("import", h, "--db", two)
    assert r.exit_code == 0 and "for the devices the file names" in r.stdout, r.output
    with Store.open(one) as a, Store.open(two) as b:
        for url, n in (("anc300://h:7230", 5), ("mm3a://COM3", 4)):
            assert b.count_traverses(url) == n
            assert list(b.iter_provenance(device=url)) == list(a.iter_provenance(device=url))
    assert _cli("import", h, "--db", two, "-d", "mm3a://com3").exit_code == 2  # anc300's rows are not mm3a's

    v1 = tmp_path / "v1.jsonl"  # as export --json wrote it before: no device
    v1.write_text("\n".join([json.dumps({"format": "stickslip-history", "version": 1}),
                             *[json.dumps({k: v for k, v in json.loads(x).items() if k != "device"})
                               for x in lines[6:]]]) + "\n", encoding="utf-8")
    r = _cli("import", v1, "--db", three)
    assert r.exit_code == 2 and " ".join(r.stderr.split()) == (
        f"error: {v1}: rows 2-5: no device named (a history file of version 1, or a row that leaves it out): give it "
        "with --device URL"), r.stderr
    assert _cli("import", v1, "--db", three, "-d", "sim://?seed=7").exit_code == 0
    with Store.open(three) as s:
        assert s.count_traverses("sim://?seed=7") == 4 and s.count_traverses() == 4

    bad = tmp_path / "bad.jsonl"  # a device field in a version-1 file is as unknown as it was to version 1
    bad.write_text("\n".join([json.dumps({"format": "stickslip-history", "version": 1}), lines[1]]) + "\n",
                   encoding="utf-8")
    r = _cli("import", bad, "--db", three, "-d", "sim://")
    assert r.exit_code == 2 and "unknown field 'device'" in r.stderr, r.stderr


def test_a_table_without_its_device_is_refused_before_a_store_is_made(tmp_path):
    from synth import paper_table

    from stickslip.measurements import write_measurements

    write_measurements(tmp_path / "m.csv", paper_table()[:2])
    r = _cli("import", tmp_path / "m.csv", "--db", tmp_path / "s.db")
    assert r.exit_code == 2 and " ".join(r.stderr.split()) == (
        f"error: {tmp_path / 'm.csv'} is a measurement table, which does not say its device: give the device it "
        "was measured on (--device URL, e.g. mm3a:///dev/ttyUSB0 or sim://)"), r.stderr
    assert not (tmp_path / "s.db").exists()


_SPELLINGS = ["sim://", "sim://?seed=3", "mm3a:///COM3", "MM3A://com3?timeout=5", "anc300://u:pw@h:7230?password=x",
              "anc300://h:7230", "mm3a:///COM3#arm=left", "mm3a:///COM3#arm=Left", None]
"""Devices a history row may name, several spellings of one among them (None: a row that names none)."""


@st.composite
def _history_rows(draw: st.DrawFn) -> tuple[Traverse, object]:
    from stickslip.measurements.history_file import Provenance

    joint = draw(st.sampled_from([1, 2, 3]))
    t = _row(day=draw(st.sampled_from(["2026-11-20", "2026-11-21", "run A"])), joint=joint,
             q2=draw(st.sampled_from([-1.0, -0.5, 0.25])), q3=draw(st.sampled_from([0.0, 0.004])),
             start=0.0, end={1: 0.3, 2: 0.1, 3: 0.01}[joint], steps=draw(st.integers(1, 10**6)))
    when = dt.datetime(2026, 11, 20, 9, draw(st.integers(0, 59)), tzinfo=dt.UTC).isoformat(timespec="microseconds")
    prov = Provenance(draw(st.sampled_from(["audio", "camera", "imported"])), when, draw(st.one_of(st.none(), _TEXT)),
                      draw(st.one_of(st.none(), _TEXT.filter(str.strip))), draw(st.sampled_from(_SPELLINGS)))
    return t, prov


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(_history_rows(), min_size=1, max_size=12))
def test_a_history_of_several_devices_moved_with_export_json_is_the_same_record(tmp_path, rows):
    """Rows of several devices (spellings of one among them, a password, two arms of one controller, rows naming
    none), stored, exported as a history file, imported into an empty store without --device: every row back under
    its device's stored name, with its provenance, in the order recorded; imported again, all refused as stored."""
    from stickslip.measurements.history_file import write_history
    from stickslip.procedures.table_import import ImportRefused, import_table

    n = next(_examples)
    home, moved, there = tmp_path / f"home{n}.db", tmp_path / f"h{n}.jsonl", tmp_path / f"there{n}.db"
    with Store.open(home) as s:
        s.add_with_provenance(rows)
        want = list(s.iter_provenance())
        write_history(moved, s.iter_provenance())
    assert b"u:pw@" not in moved.read_bytes() and b"password=x" not in moved.read_bytes()  # no device's password
    with Store.open(there) as s:
        assert len(import_table(s, moved, None).ids) == len(rows)
        got = list(s.iter_provenance())
        with pytest.raises(ImportRefused, match=f"{len(rows)} of {len(rows)} rows are already stored"):
            import_table(s, moved, None, force=True)
    assert got == want
    assert {p.device for _, p in got} <= {"sim://", "sim://?seed=3", "mm3a://com3", "anc300://h:7230",
                                          "mm3a://com3#arm=left", "mm3a://com3#arm=Left"}


def test_a_history_of_rows_alternating_three_devices_imports_on_both_backends(db, tmp_path):
    """Every line another device, the same traverse under each (not a duplicate across devices), imported with -d
    as another spelling of the one device a file names, refused for another device; on SQLite and PostgreSQL."""
    from typer.testing import CliRunner

    from stickslip.cli import app
    from stickslip.measurements import HEADER

    head = json.dumps({"format": "stickslip-history", "version": 2}) + "\n"
    devices = ["sim://", "anc300://u:pw@h", "mm3a:///COM3"]
    lines = []
    for k in range(30):
        t = _row(steps=10 + k // 3)
        lines.append(json.dumps({**{h: getattr(t, h) for h in HEADER}, "device": devices[k % 3]}))
    three, one = tmp_path / "three.jsonl", tmp_path / "one.jsonl"
    three.write_text(head + "\n".join(lines) + "\n")
    one.write_text(head + "\n".join(lines[2::3]) + "\n")
    run = CliRunner().invoke
    r = run(app, ["import", str(three), "--db", str(db)])
    assert r.exit_code == 0 and "imported 30 traverses" in r.stdout, r.output
    with Store.open(db) as s:
        assert {d: s.count_traverses(d) for d in ("sim://", "anc300://h", "mm3a://com3")} == dict.fromkeys(
            ("sim://", "anc300://h", "mm3a://com3"), 10)
        assert all("pw" not in d["url"] for d in s.devices())
    r = run(app, ["import", str(one), "--db", str(db), "-d", "MM3A://com3?timeout=5", "--force"])
    assert r.exit_code == 2 and "10 of 10 rows are already stored for mm3a://com3" in " ".join(r.stderr.split())
    r = run(app, ["import", str(one), "--db", str(db), "-d", "sim://", "--force"])
    said = " ".join(r.stderr.split())
    assert r.exit_code == 2 and "rows 2-11: the file names the device mm3a://com3, not sim:// (--device)" in said, said


@pytest.mark.parametrize(("device", "said"), [
    ("#arm=x", "row 3: the device it names, \"#arm=x\", is none: device URL '' has no scheme"),
    ("anc300://u:pw@h:xx", "row 3: the device it names, \"anc300://u:***@h:xx\", is none: malformed device URL"),
])
def test_a_history_row_naming_no_device_is_refused_with_the_name_it_gives(tmp_path, device, said):
    """It said 'row 3: device device URL '' has no scheme' for '#arm=x' (the URL before the arm: empty), the name
    the row gives not shown; now that name, its password redacted."""
    from stickslip.measurements import HEADER, TableError
    from stickslip.procedures.table_import import import_table

    path = tmp_path / "h.jsonl"
    rows = [json.dumps({**{h: getattr(_row(steps=10 + k), h) for h in HEADER}, "device": d})
            for k, d in enumerate(["sim://", device])]
    path.write_text(json.dumps({"format": "stickslip-history", "version": 2}) + "\n" + "\n".join(rows) + "\n")
    with Store.open(tmp_path / "s.db") as s, pytest.raises(TableError) as e:
        import_table(s, path, None)
    assert said in str(e.value) and "pw" not in str(e.value), str(e.value)


def test_a_version_2_row_naming_no_device_is_not_called_a_version_1_file(tmp_path):
    """A version-2 file whose rows leave "device" out (a hand-made file, another tool's) was told 'no device named
    (a history file of version 1)'; it names the version it is not, now both cases."""
    from stickslip.measurements import HEADER, TableError
    from stickslip.procedures.table_import import import_table

    path = tmp_path / "h.jsonl"
    rows = [json.dumps({**{h: getattr(_row(steps=10 + k), h) for h in HEADER}, **({"device": "sim://"} if k else {})})
            for k in range(2)]
    path.write_text(json.dumps({"format": "stickslip-history", "version": 2}) + "\n" + "\n".join(rows) + "\n")
    with Store.open(tmp_path / "s.db") as s, pytest.raises(TableError) as e:
        import_table(s, path, None)
    said = " ".join(str(e.value).split())
    assert "row 2: no device named (a history file of version 1, or a row that leaves it out)" in said, said
