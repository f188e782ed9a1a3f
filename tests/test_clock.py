"""The calendar: one "today" (local date, pinnable), calibration ages, and the date-sensitive commands
run at a far-future date and just after midnight in a UTC+14 zone.

Every date here is either pinned through ``$STICKSLIP_TODAY`` or relative to the pinned
day; the subprocess checks fake the machine's clock with libfaketime (which reaches
subprocesses) and skip with the reason when it is not installed.
"""

import dataclasses
import datetime as dt
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from synth import paper_table
from typer.testing import CliRunner

from stickslip import clock
from stickslip.cli import app
from stickslip.measurements import measurements_to_csv

runner = CliRunner()
FAR = dt.date(2099, 12, 31)  # a pinned day far in the future, at a year's end


def _day(offset: int, base: dt.date = FAR) -> str:
    return (base + dt.timedelta(days=offset)).isoformat()


# ---------------------------------------------------------------- the clock itself


def test_today_is_pinned_by_the_environment(monkeypatch):
    monkeypatch.setenv(clock.ENV_TODAY, "2099-12-31")
    assert clock.today() == FAR and clock.today_label() == "2099-12-31"
    monkeypatch.setenv(clock.ENV_TODAY, "31/12/2099")
    with pytest.raises(ValueError, match="STICKSLIP_TODAY='31/12/2099' is not a date; use YYYY-MM-DD"):
        clock.today()
    monkeypatch.delenv(clock.ENV_TODAY)
    assert clock.today() == dt.date.today()  # unpinned: the machine's local date


def test_now_is_utc():
    t = clock.now_utc()
    assert t.utcoffset() == dt.timedelta(0)


def test_age_in_calendar_days_across_a_leap_year_end():
    assert clock.age_days("2099-12-31", "2100-01-01") == 1
    assert clock.age_days("2096-02-28", "2096-03-01") == 2  # 2096 is a leap year
    assert clock.age_days("2100-02-28", "2100-03-01") == 1  # 2100 is not
    assert clock.age_days("2026-11-22 morning", "2026-11-23") == 1  # a label that starts with a date
    assert clock.age_days("2026-11-24", "2026-11-23") == -1  # dated ahead of the clock
    assert clock.age_days("day1", "2026-11-23") is None and clock.age_days(None, "2026-11-23") is None
    assert clock.age_days("2099-12-28", FAR) == 3


def test_stale_message_uses_the_pinned_today(monkeypatch):
    monkeypatch.setenv(clock.ENV_TODAY, FAR.isoformat())
    assert clock.stale_message(FAR.isoformat()) is None
    msg = clock.stale_message(_day(-400))
    assert msg.startswith(f"calibration is from {_day(-400)}, today is 2099-12-31 (400 days old): recalibrate")
    assert clock.stale_message(_day(+1)) is None  # a calibration dated ahead of today is not stale
    assert clock.stale_message(_day(+2)) is None  # ... up to the two days time zones can differ by


def test_a_calibration_dated_further_ahead_than_time_zones_explain_is_warned_about(monkeypatch):
    # a machine whose clock is a year behind (a dead RTC battery) sees every calibration made elsewhere in its
    # future: never stale before, however old it really is
    monkeypatch.setenv(clock.ENV_TODAY, "2025-11-22")
    msg = clock.stale_message("2026-11-22", max_age_days=7)
    assert msg is not None and msg.startswith(
        "calibration is from 2026-11-22, today is 2025-11-22 (365 days ahead, more than time zones explain): "
        "this machine's clock or the label is wrong"
    )
    assert clock.stale_message("2025-11-25") is not None and clock.stale_message("2025-11-24") is None


# ---------------------------------------------------------------- commands at a pinned far-future date


@pytest.fixture()
def far_future(monkeypatch, tmp_path):
    monkeypatch.setenv(clock.ENV_TODAY, FAR.isoformat())
    return tmp_path


def _calibration(tmp, day: str):
    meas = tmp / f"meas-{day}.csv"
    meas.write_text(measurements_to_csv(paper_table(day=day)))
    out = tmp / f"cal-{day}.json"
    r = runner.invoke(app, ["calibrate", str(meas), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return out


def test_plan_warns_after_its_result_when_the_calibration_is_old(far_future):
    cal = _calibration(far_future, _day(-3))
    r = runner.invoke(app, ["plan", "-c", str(cal), "--joint", "3", "--from", "1mm", "--to", "2mm", "--q2", "-90deg"])
    assert r.exit_code == 0, r.output
    assert "steps" in r.stdout
    assert r.stderr.startswith(f"warning: calibration is from {_day(-3)}, today is 2099-12-31 (3 days old)")
    fresh = _calibration(far_future, FAR.isoformat())
    r = runner.invoke(app, ["plan", "-c", str(fresh), "--joint", "3", "--from", "1mm", "--to", "2mm"])
    assert r.exit_code == 0 and r.stderr == ""


def test_a_failed_command_shows_only_its_error(far_future):
    cal = _calibration(far_future, _day(-3))
    r = runner.invoke(app, ["plan", "-c", str(cal), "--joint", "3", "--from", "1mm", "--to", "20mm"])
    assert r.exit_code == 2
    assert r.stderr.startswith("error: ") and "warning" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def _repeats(days: list[str], seed: int = 0):
    """Three readings a day at the paper's ANOVA pose of joint 3, each day 2 % apart (a clear day effect)."""
    rng = np.random.default_rng(seed)
    rows = []
    for k, day in enumerate(days):
        table = paper_table(day=day)
        for t in (table[0], table[3]):  # 3+ and 3- at (q2, theta, psi) = (-90deg, 0, 0)
            for _ in range(3):
                steps = round(t.steps * (1 + 0.02 * k) * (1 + 0.001 * rng.standard_normal()))
                rows.append(dataclasses.replace(t, steps=steps))
    return rows


def test_history_export_and_anova_keep_day_labels_across_a_year_end(far_future):
    days = [_day(-1), _day(0), _day(+1)]  # 2099-12-30, 2099-12-31, 2100-01-01
    table = far_future / "repeats.csv"
    table.write_text(measurements_to_csv(_repeats(days)))
    db = far_future / "s.db"
    r = runner.invoke(app, ["import", str(table), "--db", str(db), "--device", "sim://"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["history", "--db", str(db), "--json"])
    assert r.exit_code == 0, r.output
    assert [e["day"] for e in json.loads(r.stdout)] == days
    r = runner.invoke(app, ["export", "--db", str(db), "--day", "2100-01-01", "-o", str(far_future / "x.csv")])
    assert r.exit_code == 0, r.output
    assert (far_future / "x.csv").read_text().count("2100-01-01") == 6
    r = runner.invoke(app, ["anova", str(table), "--json"])
    assert r.exit_code == 0, r.output
    tests = json.loads(r.stdout)
    day_tests = [t for t in tests if t["test"] == "day"]
    assert len(day_tests) == 2 and all(t["significant"] for t in day_tests)
    assert {t["day"] for t in tests if t["test"] == "direction"} == set(days)


@pytest.mark.slow
def test_report_says_when_the_calibration_predates_the_data(far_future):
    pytest.importorskip("matplotlib")
    cal = _calibration(far_future, _day(-2))
    table = far_future / "meas.csv"
    table.write_text(measurements_to_csv(paper_table(day=_day(0))))
    r = runner.invoke(app, ["report", str(table), "-c", str(cal), "-o", str(far_future / "rep"), "--json"])
    assert r.exit_code == 0, r.output
    assert f"calibration is from {_day(-2)}, 2 day(s) before the latest data ({_day(0)})" in r.stderr


# ---------------------------------------------------------------- the machine's clock faked (libfaketime)


def _faked_env(faketime: str, tz: str) -> dict[str, str]:
    libfaketime = pytest.importorskip("libfaketime", reason="libfaketime (pip, in the dev extra) fakes the clock")
    _, extra = libfaketime.get_reload_information()
    env = {k: v for k, v in os.environ.items() if k != clock.ENV_TODAY}
    env.update(extra, FAKETIME=faketime, TZ=tz)
    return env


def _run(env, *code_or_args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *code_or_args], env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_just_after_midnight_in_utc_plus_14_today_is_the_local_date(tmp_path):
    # 00:00:30 on 1 January 2028 at UTC+14 is still 31 December 2027 at UTC.
    env = _faked_env("@2028-01-01 00:00:30", "Etc/GMT-14")
    r = _run(env, "-c", "from stickslip import clock; print(clock.today_label(), clock.now_utc().date())")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["2028-01-01", "2027-12-31"]
    cal = _calibration(tmp_path, "2027-12-31")
    main = "import sys; from stickslip.cli import main; sys.argv[0] = 'stickslip'; main()"
    r = _run(env, "-c", main, "plan", "-c", str(cal), "--joint", "3", "--from", "1mm", "--to", "2mm")
    assert r.returncode == 0, r.stderr
    assert "calibration is from 2027-12-31, today is 2028-01-01 (1 day old)" in r.stderr


def test_unpinned_today_follows_the_faked_machine_clock(tmp_path):
    env = _faked_env("@2028-02-29 12:00:00", "America/Los_Angeles")  # a leap day, UTC-8
    r = _run(env, "-c", "from stickslip import clock; print(clock.today_label(), clock.now_utc().isoformat()[:13])")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["2028-02-29", "2028-02-29T20"]


# ---------------------------------------------------------------- session labels


@pytest.mark.parametrize(
    "label, reason",
    [
        ("2026-13-45", "month must be in 1..12"),
        ("2026-02-29", "day is out of range"),  # not a leap year
        ("2026-11-221", "day is out of range"),
        ("2026-2-3", "write the date as 2026-02-03"),
        ("2026-99999999999999999999-1", "not one"),
        ("", "empty"),
        ("   ", "empty"),
        ("day\t1", "control character"),
        ("2026-11-22\nrm", "control character"),
        ("x" * 65, "65 characters"),
    ],
)
def test_a_label_that_cannot_be_a_session_day_says_why(label, reason):
    why = clock.day_label_problem(label)
    assert why is not None and reason in why
    with pytest.raises(ValueError, match="session label"):
        clock.check_day_label(label)


@pytest.mark.parametrize(
    "label", ["2026-11-22", "2028-02-29 am", " 2026-11-22 ", "day1", "morning", "20261122", "x" * 64]
)
def test_free_session_labels_and_real_dates_are_kept(label):
    assert clock.day_label_problem(label) is None
    assert clock.check_day_label(label) == label.strip()


@given(st.dates(min_value=dt.date(1000, 1, 1)), st.sampled_from(["", " am", " pm", "T09:00", "-run2"]))
def test_every_real_iso_date_is_a_label(date, tail):
    assert clock.day_label_problem(date.isoformat() + tail) is None


def test_a_table_row_with_an_impossible_date_is_refused_naming_its_row(tmp_path):
    rows = paper_table()[:4]
    path = tmp_path / "meas.csv"
    text = measurements_to_csv(rows)
    lines = text.splitlines()
    day = lines[3].split(",")[0]
    lines[3] = lines[3].replace(day, "2026-13-45", 1)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    r = runner.invoke(app, ["fit", str(path)])
    assert r.exit_code == 2
    assert f"{path}:4: day: the session label '2026-13-45' starts like a date but is not one" in r.output
    assert "Traceback" not in r.output


def test_traverse_and_demo_refuse_an_impossible_day_before_anything_moves(tmp_path, monkeypatch):
    monkeypatch.setenv("STICKSLIP_TODAY", "2026-11-25")
    db = tmp_path / "s.sqlite"
    r = runner.invoke(app, ["demo", "--day", "2026-02-30", "--out", str(tmp_path / "out"), "--db", str(db)])
    assert r.exit_code == 2 and "day is out of range for month" in r.output
    assert not (tmp_path / "out").exists() and not db.exists()
    r = runner.invoke(
        app, ["demo", "--device", "sim://?day=2026-2-30", "--out", str(tmp_path / "out"), "--db", str(db)]
    )
    assert r.exit_code == 2 and "day is out of range for month" in r.output
    assert not (tmp_path / "out").exists() and not db.exists()
    r = runner.invoke(app, ["traverse", "-j", "3", "--direction", "+", "--tuning", "t.json", "--day", "2026-1-5"])
    assert r.exit_code == 2 and "write the date as 2026-01-05" in r.output


@given(st.dates(), st.dates())
def test_natural_order_sorts_iso_dates_as_dates(a, b):
    from stickslip.records import natural_order

    assert (natural_order(a.isoformat()) < natural_order(b.isoformat())) == (a < b)


def test_a_calibration_of_sessions_day9_and_day10_is_dated_day10():
    """The calibration's day is its table's latest session: labels were compared as text, so of day9 and day10
    the calibration was dated day9 (audit31)."""
    from stickslip.calibration import calibrate
    from stickslip.records import natural_order

    assert sorted(["day10", "day9", "day1"], key=natural_order) == ["day1", "day9", "day10"]
    rows = paper_table()
    half = len(rows) // 2
    table = [dataclasses.replace(t, day="day9") for t in rows[:half]] + [
        dataclasses.replace(t, day="day10") for t in rows[half:]]
    cal = calibrate(table)
    assert cal.day == "day10"
    assert cal.provenance.days == ("day9", "day10")


def test_a_label_with_an_invisible_character_names_it():
    # a zero-width space was called "a control character (a tab or a line break)" (audit42): the code point now
    from stickslip.clock import day_label_problem

    why = day_label_problem("2026-11-22\u200b")
    assert why is not None and "U+200B" in why and "zero-width space" in why
    assert "U+0009" in (day_label_problem("day\t1") or "")
    assert day_label_problem("2026-11-22 pm") is None
