"""``stickslip demo`` and :func:`stickslip.procedures.demo.run_demo`: the whole story on the simulator.

Acceptance (issue 3): calibrated a and gamma0 within 1 % of the simulator's truth, b
within 0.01, c and d within 3 % (or 0.5 µrad for d). The truth is
``SimulatedMM3A.true_parameters()``; its definition (what Eq. 3/8 need to reproduce the
simulator's mean behaviour) is tested in test_simulator.py.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from stickslip.calibration import Calibration
from stickslip.cli import app
from stickslip.measurements import read_measurements
from stickslip.procedures.demo import CALIBRATION_PLAN, REPEAT_PLAN, VALIDATION_PLAN, run_demo

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

runner = CliRunner()


def _check_acceptance(parameters: list[dict]) -> None:
    names = sorted((p["joint"], p["direction"], p["name"], p["q3"]) for p in parameters)
    assert len(names) == 6 + 8  # joint 3: a, b, c per direction; joint 2: gamma0, d at 2 q3 each
    for p in parameters:
        value, true = p["value"], p["true"]
        where = f"{p['joint']}{p['direction']} {p['name']} q3={p['q3']}: {value!r} vs {true!r}"
        if p["name"] in ("a", "gamma0"):
            assert value == pytest.approx(true, rel=0.01), where
        elif p["name"] == "b":
            assert value == pytest.approx(true, abs=0.01), where
        elif p["name"] == "c":
            assert value == pytest.approx(true, rel=0.03), where
        else:  # d
            assert abs(value - true) <= max(0.03 * abs(true), 0.5e-6), where
        assert p["unit"] == {"a": "m", "b": "1", "c": "m", "gamma0": "rad", "d": "rad"}[p["name"]]
        assert (p["q3"] is None) == (p["joint"] == 3)


def _check_summary(data: dict, seed: int, day: str, out) -> None:
    """The demo's --json summary on the tuned audio switch (virtual microphone), 14 traverses: within tolerance."""
    assert data["elapsed_s"] > 0 and data["seed"] == seed and data["day"] == day
    for p in data["parameters"]:
        assert {"joint", "direction", "name", "value", "true", "unit"} <= set(p)
    _check_acceptance(data["parameters"])
    assert len(data["traverses"]) == 14
    assert (out / "measurements.csv").exists() and (out / "calibration.json").exists()
    assert (out / "tuning-joint2.json").exists()


class FakeStore:
    def __init__(self):
        self.traverses, self.calibrations = [], []

    def add_traverse(self, traverse, device="sim://", how="measured"):
        self.traverses.append((traverse, device, how))
        return len(self.traverses)

    def add_calibration(self, cal, device, traverse_ids=None):
        self.calibrations.append((cal, device, traverse_ids))
        return 1


def test_run_demo_with_the_oracle_switch_saves_and_recovers_the_truth(tmp_path):
    """Fast path (no sound rendered): the same procedure, the switch knows the true stops."""
    store, seen = FakeStore(), []
    res = run_demo(
        seed=4, day="2026-11-22", out=tmp_path / "out", switch="oracle", store=store, on_traverse=seen.append
    )
    n_cal, n_val = 2 * len(CALIBRATION_PLAN), 2 * len(VALIDATION_PLAN)
    n_rep = 2 * 2 * len(REPEAT_PLAN)  # two more readings each way at the paper's ANOVA poses (default repeats=2)
    assert (len(res.traverses), len(res.validation_traverses), len(res.repeat_traverses), len(seen)) == (
        14, n_val, n_rep, 14 + n_val + n_rep)
    # with the calibration traverse, each ANOVA pose now has three readings per direction (Section 3.1)
    rows = [r.traverse for r in res.traverses + res.repeat_traverses]
    for joint, pose in REPEAT_PLAN:
        for d in "+-":
            same = [t for t in rows if t.joint == joint and t.direction == d
                    and all(abs(getattr(t, k) - v) < 1e-12 for k, v in pose.items())]
            assert len(same) == 3
    assert res.calibration.method == "paper"
    _check_acceptance([c.to_dict() for c in res.parameters])
    # the model beats the constant step on the validation sweep (paper: 15 % vs 40 %, 2 % vs 7 %)
    for row in res.validation.rows():
        assert row["model_max_rel_error"] < 0.01
        assert row["constant_max_rel_error"] > 5 * row["model_max_rel_error"]
    # files
    out = tmp_path / "out"
    assert [t.steps for t in read_measurements(out / "measurements.csv")] == [r.traverse.steps for r in res.traverses]
    assert len(read_measurements(out / "validation.csv")) == n_val
    assert len(read_measurements(out / "repeats.csv")) == n_rep
    cal = Calibration.load(out / "calibration.json")
    assert cal.parameters() == res.calibration.parameters()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["elapsed_s"] == pytest.approx(res.elapsed_s)
    # storage hook
    assert len(store.traverses) == n_cal + n_val + n_rep
    assert {d for _, d, _ in store.traverses} == {"sim://?seed=4"}  # the arm, not the session
    assert store.calibrations[0][2] == list(range(1, n_cal + 1))
    # compute, then plot: one point per parameter, in % of the truth
    ax = res.plot()
    (points,) = [line for line in ax.lines if line.get_marker() == "o"]
    assert len(points.get_xdata()) == len(res.parameters)
    assert max(abs(v) for v in points.get_ydata()) < 1.0


def test_run_demo_rejects_bad_settings():
    with pytest.raises(ValueError, match="listen_from"):
        run_demo(out=None, listen_from=1.5)
    with pytest.raises(ValueError, match="switch"):
        run_demo(out=None, switch="magic")


def test_cli_demo_bad_output_folder_is_one_line_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    r = runner.invoke(app, ["demo", "--out", str(blocker / "sub"), "--no-validation", "--json"])
    assert r.exit_code == 2
    text = r.stderr if hasattr(r, "stderr") else r.output
    assert text.startswith("error:") and "Traceback" not in text


def test_cli_demo_refuses_a_results_file_it_could_not_write_before_running(tmp_path):
    """audit25: a folder named calibration.json in --out was found after the run, measurements.csv and repeats.csv
    already replaced (a mixed folder: this run's tables beside an earlier calibration)."""
    (tmp_path / "calibration.json").mkdir()
    (tmp_path / "measurements.csv").write_text("an earlier run's\n")
    r = runner.invoke(app, ["demo", "--out", str(tmp_path), "--no-db", "--no-validation"])
    assert r.exit_code == 2 and r.stderr == (f"error: {tmp_path / 'calibration.json'}: is a folder, not a file; give "
                                             "the path of a file to write the results to\n"), r.output
    assert (tmp_path / "measurements.csv").read_text() == "an earlier run's\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calibration.json", "measurements.csv"]


def test_cli_demo_negative_seed_is_one_line_error(tmp_path):
    r = runner.invoke(app, ["demo", "--seed", "-3", "--out", str(tmp_path)])
    assert r.exit_code == 2
    text = r.stderr if hasattr(r, "stderr") else r.output
    assert "error: seed = -3 must be an integer" in text


def test_cli_demo_help_names_units_and_example():
    r = runner.invoke(app, ["demo", "--help"])
    assert r.exit_code == 0
    assert "--seed" in r.output and "--json" in r.output and "µrad" in r.output
    assert "stickslip demo --seed" in r.output


def test_cli_demo_records_every_traverse_and_the_calibration(tmp_path):
    from stickslip.storage import Store

    db = tmp_path / "demo.db"
    out = tmp_path / "res"
    r = CliRunner().invoke(app, ["demo", "--no-validation", "--json", "--out", str(out), "--db", str(db)])
    assert r.exit_code == 0, r.output
    _check_summary(json.loads(r.stdout), seed=0, day="2026-11-22", out=out)  # the real thing, default seed
    with Store.open(db) as st:
        # the paper's 6 prismatic + 8 rotary calibration traverses, and 8 repeats for the ANOVA
        assert st.count_traverses() == 14 + 8
        cal = st.latest_calibration()
        assert cal is not None and cal.method == "paper"
        assert st.integrity_check() == "ok"
    # the simulator is deterministic: the same seed and day again would store the same traverses,
    # so a second run still runs but records nothing, and says so
    r = CliRunner().invoke(app, ["demo", "--no-validation", "--json", "--out", str(tmp_path / "res"), "--db", str(db)])
    assert r.exit_code == 0, r.output
    assert "already holds 22 traverses of sim:// on 2026-11-22" in r.stderr
    assert "not recorded again (use --allow-duplicates" in r.stderr
    with Store.open(db) as st:
        assert st.count_traverses() == 14 + 8
        assert len(st.calibrations()) == 1


def test_two_demo_days_give_the_seeds_anova_verdict(tmp_path):
    # Section 3.1: the step size differs significantly from day to day (the simulator drifts ~3 %/day)
    from stickslip.analysis import anova

    rows = []
    for day in ("2026-11-20", "2026-11-21"):
        res = run_demo(seed=6, day=day, out=None, switch="oracle", validation=False)
        rows += [r.traverse for r in res.traverses + res.repeat_traverses]
    tests = [t for t in anova(rows).tests if t.test == "day"]
    assert {(t.joint, t.direction) for t in tests} == {(3, "+"), (3, "-"), (2, "+"), (2, "-")}
    assert all(t.p < 0.05 for t in tests)


def test_demo_device_takes_a_sim_url_and_refuses_real_controllers(tmp_path):
    r = runner.invoke(app, ["demo", "--device", "mm3a:///dev/ttyUSB0", "--no-db"])
    assert r.exit_code == 2 and "stickslip traverse --device mm3a:///dev/ttyUSB0" in r.stderr
    r = runner.invoke(app, ["demo", "--device", "sim://?seed=2&day=2026-11-19&noise=1", "--no-db"])
    assert r.exit_code == 2 and "not noise" in r.stderr
    # an earlier run's validation.csv in the folder is kept as it was and named (audit25: it sat beside this run's
    # results, unsaid, and read as this draw's validation)
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "validation.csv").write_text("an earlier run's\n")
    r = runner.invoke(app, ["demo", "--device", "sim://?seed=2&day=2026-11-19", "--no-db", "--no-validation",
                            "--json", "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    assert r.stderr == (f"warning: {tmp_path / 'o' / 'validation.csv'} is from an earlier run, not this one (this "
                        "run wrote none): delete it or use another --out\n")
    assert (tmp_path / "o" / "validation.csv").read_text() == "an earlier run's\n"
    _check_summary(json.loads(r.stdout), seed=2, day="2026-11-19", out=tmp_path / "o")  # another draw


def test_demo_plot_shows_every_parameter_name_whole():
    import numpy as np
    from figures import inside_figure  # tests/support
    from synth import paper_table  # tests/support

    from stickslip.calibration import calibrate
    from stickslip.procedures.demo import DemoResult, compare_parameters

    cal = calibrate(paper_table())
    params = compare_parameters(cal.parameters(), cal.parameters())
    r = DemoResult(3, "2026-11-22", {}, [], [], cal, None, cal.parameters(), params, 0.0, 0.0)
    ax = r.plot()
    ticks = ax.get_xticklabels()
    assert len(ticks) == len(params) == 14
    assert all(inside_figure(t) for t in ticks)  # the rotated names were cut at the bottom of the figure
    np.testing.assert_allclose([ln.get_ydata()[0] for ln in ax.get_lines()[:1]], [0.0])
