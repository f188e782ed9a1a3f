"""What a calibration was made with (device, stepping frequency, amplitude, temperature), kept in
its JSON, and the warnings `move` gives when it is used elsewhere, at other settings or too late.

Reference values: the simulated arm steps at 1000 Hz on every joint (sim/arm.py); ages are
counted in calendar days from the pinned today (STICKSLIP_TODAY), never the machine's clock.
"""

from __future__ import annotations

import dataclasses
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st
from synth import paper_table
from typer.testing import CliRunner

from stickslip.calibration import Calibration, Conditions
from stickslip.cli import app
from stickslip.clock import max_age_days
from stickslip.measurements import measurements_to_csv
from stickslip.procedures.conditions import conditions_of, usage_warnings
from stickslip.sim.arm import SimulatedMM3A

runner = CliRunner()
DAY = "2026-11-22"


def _cal(conditions: Conditions = Conditions(), day: str = DAY) -> Calibration:
    sim = SimulatedMM3A(seed=4, day=DAY)
    models = sim.true_models()
    return Calibration(
        models=models,
        stderr=dict.fromkeys(models),
        constant_steps={k: 1e-6 for k in models},
        day=day,
        method="paper",
        conditions=conditions,
    )


def test_conditions_round_trip_through_the_json(tmp_path):
    c = Conditions("sim://?seed=4", 1000.0, 60.0, 21.5)
    path = tmp_path / "cal.json"
    _cal(c).save(path)
    data = json.loads(path.read_text())
    assert data["conditions"] == {"device": "sim://?seed=4", "frequency_hz": 1000.0, "amplitude_v": 60.0,
                                  "temperature_c": 21.5}
    assert Calibration.load(path).conditions == c


def test_a_calibration_file_without_conditions_still_loads(tmp_path):
    path = tmp_path / "cal.json"
    _cal().save(path)
    data = json.loads(path.read_text())
    del data["conditions"]
    path.write_text(json.dumps(data))
    loaded = Calibration.load(path)
    assert loaded.conditions == Conditions()
    assert not loaded.conditions.recorded


@pytest.mark.parametrize(
    "field, value",
    [("frequency_hz", -5.0), ("frequency_hz", float("nan")), ("frequency_hz", True), ("amplitude_v", 1e9),
     ("temperature_c", -300.0), ("frequency_hz", "1000"), ("device", 7)],
)
def test_invalid_conditions_are_refused_naming_the_field(tmp_path, field, value):
    path = tmp_path / "cal.json"
    _cal().save(path)
    data = json.loads(path.read_text())
    data["conditions"][field] = value
    path.write_text(json.dumps(data, allow_nan=True))
    # NaN is refused by the file reader for every field, before the conditions are looked at
    with pytest.raises(ValueError, match=f"conditions.{field}|NaN/Infinity are not numbers"):
        Calibration.load(path)


def test_unknown_condition_fields_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown field"):
        Conditions.from_dict({"frequency_hz": 1000.0, "humidity": 40})


@given(a=st.floats(300, 20000), r=st.floats(-0.2, 0.2))
def test_frequency_differences_beyond_one_percent_warn(a, r):
    b = a * (1 + r)
    diffs = Conditions(frequency_hz=a).differences(Conditions(frequency_hz=b))
    assert bool(diffs) == (abs(a - b) > 0.01 * max(a, b))


def test_only_fields_both_sides_record_are_compared():
    assert Conditions(device="sim://").differences(Conditions(frequency_hz=1000.0)) == []
    assert Conditions(temperature_c=20.0).differences(Conditions(temperature_c=21.9)) == []
    assert Conditions(temperature_c=20.0).differences(Conditions(temperature_c=22.1)) == [
        "temperature 20 °C then, 22.1 °C now"
    ]


def test_conditions_are_read_off_the_simulator():
    sim = SimulatedMM3A(seed=4, day=DAY)
    c = conditions_of(sim, "sim://?seed=4&day=2026-11-22")
    assert c == Conditions("sim://?seed=4", 1000.0, None, None)
    sim.set_frequency(2, 1500.0)
    assert conditions_of(sim, "sim://?seed=4").frequency_hz is None  # joints differ: not one condition
    assert conditions_of(sim, "sim://?seed=4", (2,)).frequency_hz == 1500.0


def test_usage_warnings_name_device_frequency_and_age(monkeypatch):
    monkeypatch.setenv("STICKSLIP_TODAY", "2026-11-25")
    sim = SimulatedMM3A(seed=4, day=DAY)
    cal = _cal(Conditions("sim://?seed=9", 1500.0))
    w = usage_warnings(cal, sim, "sim://?seed=4", 3, max_age_days=5)
    assert len(w) == 1
    assert "made on sim://?seed=9, this is sim://?seed=4" in w[0]
    assert "stepping frequency 1500 Hz then, 1000 Hz now" in w[0]
    w = usage_warnings(cal, sim, "sim://?seed=4", 3, max_age_days=2)
    assert w[0].startswith("calibration is from 2026-11-22, today is 2026-11-25 (3 days old)")
    same = _cal(Conditions("sim://?seed=4", 1000.0))
    assert usage_warnings(same, sim, "sim://?seed=4", 3, max_age_days=3) == []
    # a calibration file that wrote the default seed out is the same arm as plain sim://
    written_out = _cal(Conditions("sim://?seed=0", 1000.0))
    assert usage_warnings(written_out, SimulatedMM3A(seed=0, day=DAY), "sim://", 3, max_age_days=3) == []


def test_max_age_comes_from_the_option_then_the_environment(monkeypatch):
    monkeypatch.delenv("STICKSLIP_MAX_AGE_DAYS", raising=False)
    assert max_age_days() == 0
    monkeypatch.setenv("STICKSLIP_MAX_AGE_DAYS", "7")
    assert max_age_days() == 7
    assert max_age_days(2) == 2
    monkeypatch.setenv("STICKSLIP_MAX_AGE_DAYS", "a week")
    with pytest.raises(ValueError, match="STICKSLIP_MAX_AGE_DAYS"):
        max_age_days()


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_calibrate_records_conditions_without_the_password(tmp_path, monkeypatch):
    meas = tmp_path / "meas.csv"
    meas.write_text(measurements_to_csv(paper_table()))
    out = tmp_path / "cal.json"
    r = _run("calibrate", meas, "-o", out, "--device", "anc300://lab:7230?password=hunter2",
             "--frequency", "1000", "--amplitude", "40", "--temperature", "22")
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert "hunter2" not in text
    c = Calibration.load(out).conditions
    assert c == Conditions("anc300://lab:7230", 1000.0, 40.0, 22.0)
    bad = _run("calibrate", meas, "--frequency", "-3")
    assert bad.exit_code == 2 and "--frequency" in bad.output and "0.001" in bad.output  # the option, its range


def test_move_warns_before_driving_when_the_settings_differ(tmp_path, monkeypatch):
    monkeypatch.setenv("STICKSLIP_TODAY", DAY)
    path = tmp_path / "cal.json"
    dataclasses.replace(_cal(Conditions("sim://?seed=4", 1500.0))).save(path)
    r = _run("move", "-d", "sim://?seed=4", "-c", path, "--joint", "3", "--by", "30um", "--db", tmp_path / "s.db")
    assert r.exit_code == 0, r.output
    assert "stepping frequency 1500 Hz then, 1000 Hz now" in r.output
    same = tmp_path / "same.json"
    _cal(Conditions("sim://?seed=4", 1000.0)).save(same)
    r = _run("move", "-d", "sim://?seed=4", "-c", same, "--joint", "3", "--by", "30um", "--db", tmp_path / "t.db")
    assert r.exit_code == 0, r.output
    assert "other conditions" not in r.output and "recalibrate" not in r.output


def test_move_max_age_option(tmp_path, monkeypatch):
    monkeypatch.setenv("STICKSLIP_TODAY", "2026-11-30")
    path = tmp_path / "cal.json"
    _cal().save(path)
    args = ("move", "-d", "sim://?seed=4", "-c", path, "--joint", "3", "--by", "10um")
    r = _run(*args, "--db", tmp_path / "a.db", "--max-age", "10")
    assert r.exit_code == 0 and "recalibrate" not in r.output
    r = _run(*args, "--db", tmp_path / "b.db", "--max-age", "3")
    assert r.exit_code == 0 and "8 days old" in r.output
