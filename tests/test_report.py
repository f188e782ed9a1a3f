"""Seed-style figures: the numbers behind them, and the HTML report.

Reference values: the models' closed-form traverse averages (stickslip.models), the
step-by-step count of stickslip.models.simulate_traverse_steps, the exact inversion
stickslip.calibration.invert_d_exact, and Eq. 9 as printed in the paper (Section 3.5).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.calibration import Calibration, CalibrationError, calibrate, invert_d_exact
from stickslip.cli import app
from stickslip.measurements import write_measurements
from stickslip.models import JointModel, simulate_traverse_steps
from stickslip.report import (
    build_report,
    d_relation_data,
    prismatic_data,
    rotary_interval_data,
    simulate_steps,
    step_simulation_data,
    validation_data,
)
from test_analysis import TRUE_PRISMATIC, TRUE_ROTARY, simulated_table  # tests/ is on sys.path

pytest.importorskip("matplotlib")
runner = CliRunner()


@pytest.fixture(scope="module")
def table():
    return simulated_table(11, noise=0.01)


@pytest.fixture(scope="module")
def cal(table):
    return calibrate(table, method="lsq")


def test_step_simulation_counts_like_the_models_simulator_and_averages_like_the_closed_form(cal):
    sim = step_simulation_data(cal, 2)
    assert {(r["direction"], r["q3"]) for r in sim.runs} == {("-", 0.0), ("-", 0.012), ("+", 0.0), ("+", 0.012)}
    spec = kin.JOINTS[2]
    for r in sim.runs:
        m = cal.model(2, r["direction"])
        A, al, be = (float(np.asarray(x)) for x in m.rotary_coefficients(0.0, 0.0, r["q3"], 0.0, 0.0))
        n = simulate_traverse_steps(
            r["start"], r["end"], lambda q, A=A, al=al, be=be: A + al * math.cos(q) + be * math.sin(q)
        )
        assert r["steps"] == n
        # the discrete count differs from the integral by less than one step
        exact = float(m.average_gamma(r["start"], r["end"], 0.0, 0.0, r["q3"], 0.0, 0.0))
        assert abs(spec.span / exact - r["steps"]) < 1.0
        # the negative direction starts at the upper stop (pi/6), as in the paper's Fig. 8
        assert r["start"] == (spec.upper if r["direction"] == "-" else spec.lower)
        assert r["q"][0] == r["start"] and np.all(r["gamma"] > 0)
    q, g = simulate_steps(0.0, 1.0, 0.125, 0.0, 0.0)  # binary fractions: no rounding in the sums
    assert q.size == 8 and np.all(g == 0.125) and q[-1] == 0.875


def test_rotary_intervals_plot_the_exact_interval_average_at_the_midpoint(cal, table):
    fig = rotary_interval_data(cal, table, 2)
    labels = {(s.direction, s.label) for s in fig.series}
    assert labels == {(d, f"q3 = {q:.0f} mm, θ = 0°") for d in "+-" for q in (0, 12)}
    for s in fig.series:
        q3 = 0.0 if "q3 = 0 mm" in s.label else 0.012
        assert s.zeta_model.size == 8 and s.zeta_data.size == 8
        m = cal.model(2, s.direction)
        for z, g in zip(s.zeta_model, s.gamma_model, strict=True):
            mid = -z  # zeta = psi - q2 with psi = 0
            lo, hi = mid - math.pi / 12, mid + math.pi / 12
            start, end = (lo, hi) if s.direction == "+" else (hi, lo)
            assert g == pytest.approx(float(m.average_gamma(start, end, 0.0, 0.0, q3, 0.0, 0.0)), rel=1e-9)
        # the data are the table's own pi/6 traverses
        assert np.all(np.abs(np.abs(np.diff(np.sort(s.zeta_data))) - math.pi / 6) < 1e-9)
    # full-range traverses are not interval data
    assert all(np.all(np.abs(s.zeta_data - math.pi / 2) > 1e-6) for s in fig.series)


def test_rotary_intervals_without_data_draw_the_model_for_the_seeds_intervals(cal):
    fig = rotary_interval_data(cal, [], 2)
    assert len(fig.series) == 4 and all(s.zeta_model.size == 8 and s.zeta_data.size == 0 for s in fig.series)
    z = np.sort(fig.series[0].zeta_model)
    assert np.allclose(np.degrees(z), np.arange(-15, 196, 30))  # midpoints of the eight pi/6 intervals


def test_prismatic_curves_follow_eq3_per_theta(cal, table):
    fig = prismatic_data(cal, table)
    plus = [s for s in fig.series if s.direction == "+"]
    assert [s.label for s in plus] == [f"θ = {t}°, ψ = 0° (q2 varied)" for t in (0, -60, -90)]
    for s in fig.series:
        th = math.radians(float(re.search(r"θ = (-?\d+)°", s.label).group(1)))
        m = cal.model(3, s.direction)
        q2 = -s.zeta_model  # psi = 0
        assert np.allclose(s.gamma_model, m.gamma(0.0, q2, 0.0, th, 0.0), rtol=1e-12)
        assert s.zeta_data.size == 7


def test_d_relation_matches_the_exact_inversion_and_shows_eq9_printed_is_wrong(cal):
    rel = d_relation_data(cal, 2, gamma0_values=(40e-6, 80e-6), n=9, simulate="exact")
    assert rel.d_exact.shape == (2, 9)
    for i, g0 in enumerate(rel.gamma0):
        for j in (0, 2, 4, 6, 8):
            args = (g0 + rel.delta[j], g0, math.pi / 6, -7 * math.pi / 6, 0.0, -1.0)
            if np.isnan(rel.d_exact[i, j]):  # beyond the largest average this gamma0 can give
                with pytest.raises(CalibrationError, match="larger than any d"):
                    invert_d_exact(*args)
            else:
                assert rel.d_exact[i, j] == pytest.approx(invert_d_exact(*args), rel=1e-4, abs=1e-10)
    assert np.isnan(rel.d_exact[0, -1]) and np.isfinite(rel.d_exact[1]).all()
    # small D: d / D tends to range / integral of the load = 1 / mean(sin zeta) = 2.418 (docs/design.md: ~2.4-2.5)
    mean_load = (math.cos(-math.pi / 6) - math.cos(7 * math.pi / 6)) / (4 * math.pi / 3)
    slope = np.gradient(rel.d_exact[1], rel.delta)[4]
    assert slope == pytest.approx(1 / mean_load, rel=0.02)
    assert np.all(np.abs(rel.d_printed) < 1e-6)  # Eq. 9 as printed: d < 1 µrad over +-9.2 µrad
    assert np.nanmax(np.abs(rel.d_exact)) > 15e-6  # while the exact relation reaches ~ the paper's Fig. 10
    # the calibration's own points lie on the exact relation (d from the model, D from its average)
    for c in rel.calibrated:
        m = cal.model(2, c["direction"])
        g0 = float(m.params.at(c["q3"])[0])
        ref = invert_d_exact(g0 + c["delta"], g0, math.pi / 6, -7 * math.pi / 6, 0.0, -1.0)
        assert c["d"] == pytest.approx(ref, rel=1e-6)


def test_validation_data_splits_errors_per_joint(cal, table):
    v = validation_data(cal, table)
    assert v.joints == [2, 3]
    assert sum(a.size for a in v.measured.values()) == len(table)
    assert max(np.max(np.abs(e)) for e in v.model_error.values()) < 0.05  # 1 % noise
    assert max(np.max(np.abs(e)) for e in v.constant_error.values()) > 0.2  # the constant step is far off


def test_build_report_writes_figures_and_a_self_contained_page(cal, table, tmp_path):
    rep = build_report(cal, table, tmp_path / "r", dpi=40, seed_simulation="exact")
    names = sorted(p.name for p in rep.figures)
    assert names == ["fig4_prismatic.png", "fig6_rotary_intervals.png", "fig8_simulated_steps.png",
                     "fig9_d_relation.png", "validation.png"]
    for p in rep.figures:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = rep.html.read_text()
    assert sorted(re.findall(r"<img src='([^']+)'", page)) == names  # relative references only
    assert "model max" in page and "constant-step max" in page and "standard error" in page


def test_cli_report_and_fit_round_trip(tmp_path, table):
    meas, calp = tmp_path / "meas.csv", tmp_path / "cal.json"
    prism = [t for t in table if t.joint == 3]
    write_measurements(meas, prism)
    assert runner.invoke(app, ["fit", str(meas), "-o", str(calp)]).exit_code == 0
    r = runner.invoke(app, ["report", "--calibration", str(calp), str(meas), "-o", str(tmp_path / "rep"), "--json"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "rep" / "index.html").exists() and (tmp_path / "rep" / "fig4_prismatic.png").exists()
    assert Calibration.load(calp).joints == [3]
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    r = runner.invoke(app, ["report", "--calibration", str(bad), str(meas), "-o", str(tmp_path / "x")])
    assert r.exit_code == 2 and "not a stickslip calibration" in r.output


def test_truth_is_what_the_generator_uses():
    # guard: the figures' tests assume these models are physical
    for d in "+-":
        JointModel(3, d, TRUE_PRISMATIC[d]).params.check_physical()
        JointModel(2, d, TRUE_ROTARY[d]).params.check_physical()
