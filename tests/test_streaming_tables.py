"""predict and import stream their tables a chunk at a time (issue 33): the same output and messages as
reading the table whole, with no size limit and memory bounded by a chunk."""

from __future__ import annotations

import json

import numpy as np
import pytest
from synth import history_csv
from typer.testing import CliRunner

import stickslip.measurements.chunks as chunks
from stickslip.calibration import Calibration, calibrate
from stickslip.cli import app
from stickslip.measurements import parse_measurements, read_pose_columns, stream_measurement_table
from stickslip.storage import Store

pytestmark = pytest.mark.xdist_group("streaming_tables")  # one worker calibrates `cal_path` once
runner = CliRunner()


@pytest.fixture(scope="session")
def cal_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("cal") / "cal.json"
    calibrate(parse_measurements(history_csv(300), "h.csv"), model="auto").save(path)
    return path


def _poses(path, n=50, bad_line=None):
    rng = np.random.default_rng(3)
    lines = ["joint,direction,q1,q2,q3,theta,psi,start,end,note"]
    for i in range(n):
        if i % 2:
            lines.append(f"3,+,0,{rng.uniform(-3, 0.3):.6g},0,{rng.uniform(-1, 1):.6g},0,,,\"a, {i}\"")
        else:
            lines.append(f"2,,0,0,{rng.uniform(0, 0.012):.6g},{rng.uniform(-1, 1):.6g},0,0.5,-3.5,n{i}")
    if bad_line is not None:
        lines[bad_line] = "3,+,0,banana,0,0,0,,,x"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("interval", [False, True])
def test_predict_in_small_chunks_writes_what_one_chunk_writes(tmp_path, cal_path, monkeypatch, interval):
    poses = _poses(tmp_path / "p.csv")
    extra = ["--interval"] if interval else []
    whole = runner.invoke(app, ["predict", "-c", str(cal_path), str(poses), *extra])
    assert whole.exit_code == 0, whole.output
    monkeypatch.setattr(chunks, "CHUNK_ROWS", 7)  # quoted cells with commas cross chunk boundaries
    small = runner.invoke(app, ["predict", "-c", str(cal_path), str(poses), *extra])
    assert small.stdout == whole.stdout
    js = runner.invoke(app, ["predict", "-c", str(cal_path), str(poses), "--json", *extra])
    rows = json.loads(js.stdout)
    assert len(rows) == 50 and rows[1]["note"] == "a, 1" and ("gamma_pi95" in rows[0]) == interval
    table = read_pose_columns(poses)  # the columns read whole predict the same steps
    assert [r["gamma_pred"] for r in rows[::2]] == pytest.approx(
        Calibration.load(cal_path).model(2, "-").average_gamma(
            table.start[::2], table.end[::2], table.q1[::2], table.q2[::2], table.q3[::2], table.theta[::2],
            table.psi[::2]).tolist(), rel=1e-12)


def test_a_bad_row_at_the_end_leaves_no_output(tmp_path, cal_path, monkeypatch):
    monkeypatch.setattr(chunks, "CHUNK_ROWS", 7)
    poses = _poses(tmp_path / "p.csv", bad_line=49)
    out = tmp_path / "out.csv"
    r = runner.invoke(app, ["predict", "-c", str(cal_path), str(poses), "-o", str(out)])
    assert r.exit_code == 2 and f"{poses}:50: q2" in r.stderr and not out.exists()
    r = runner.invoke(app, ["predict", "-c", str(cal_path), str(poses)])  # to the terminal: nothing printed
    assert r.exit_code == 2 and r.stdout == ""


def test_import_streams_and_stores_all_or_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(chunks, "CHUNK_ROWS", 9)
    good = tmp_path / "h.csv"
    good.write_text(history_csv(120))
    db = tmp_path / "db.sqlite"
    r = runner.invoke(app, ["import", str(good), "-d", "sim://", "--db", str(db), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["imported"] == 120
    with Store.open(db) as st:
        stored = st.traverses()
    assert stored == [t for part in stream_measurement_table(good) for t in part.traverses()]
    lines = history_csv(60, seed=4).splitlines()
    lines[55] = lines[55].replace(",3,", ",7,", 1) if ",3," in lines[55] else lines[55].replace(",2,", ",7,", 1)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    r = runner.invoke(app, ["import", str(bad), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2 and f"{bad}:56:" in r.stderr
    with Store.open(db) as st:
        assert st.count_traverses() == 120  # nothing of the bad table
    r = runner.invoke(app, ["import", str(good), "-d", "sim://", "--db", str(db)])
    assert r.exit_code == 2 and "imported before" in r.stderr


def test_calibrate_reads_its_table_whole_so_its_cap_is_an_option_with_the_reason(tmp_path):
    table = tmp_path / "h.csv"
    table.write_text(history_csv(3_000))  # about 220 kB
    r = runner.invoke(app, ["calibrate", str(table), "--max-table-mb", "0.1"])
    assert r.exit_code == 2
    assert "held in memory" in r.stderr and "--max-table-mb raises the limit" in r.stderr
    r = runner.invoke(app, ["calibrate", str(table), "--max-table-mb", "-3"])
    assert r.exit_code == 2 and "--max-table-mb must be a positive number" in r.stderr
