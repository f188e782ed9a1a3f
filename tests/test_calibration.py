"""Calibration: the paper's values, the exact rotary inversion, the Eq. 9 comparator, least squares."""

import json
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from synth import PAPER_PRISMATIC, PAPER_ROTARY, paper_table, random_poses, traverse_from_model

from stickslip import calibration as C
from stickslip.calibration.inversion import _simulate_full_range_averages
from stickslip.kinematics import JOINTS
from stickslip.measurements import Traverse
from stickslip.models import JointModel, PrismaticParams, steps_between

LO, HI = JOINTS[2].lower, JOINTS[2].upper
SPAN = HI - LO


def exact_prismatic_rows(params=PAPER_PRISMATIC, order=(0, 1, 2)):
    """Traverses whose average step is exactly Eq. 3 at the paper's poses (no rounding of the model)."""
    poses = list(C.PRISMATIC_PAPER_POSES.values())
    rows = []
    for d, p in params.items():
        model = JointModel(3, d, p)
        for i in order:
            q2, th, ps = poses[i]
            g = float(model.gamma(0, q2, 0, th, ps))
            n = math.floor(0.012 / g)
            start = 0.0 if d == "+" else 0.012
            end = start + (n * g if d == "+" else -n * g)
            rows.append(Traverse("2026-11-22", 3, d, 0.0, q2, 0.0, th, ps, start, end, n))
    return rows


@pytest.mark.parametrize("order", [(0, 1, 2), (1, 2, 0), (2, 0, 1)])
def test_paper_prismatic_values_recovered_exactly_in_any_order(order):
    # Fig. 4b caption: a+ = 972, b+ = 0.27, c+ = 372, a- = 899, b- = 0.25, c- = -436 (nm)
    cal = C.calibrate(exact_prismatic_rows(order=order), method="paper")
    for d, p in PAPER_PRISMATIC.items():
        got = cal.model(3, d).params
        assert got.a == pytest.approx(p.a, rel=1e-12)
        assert got.b == pytest.approx(p.b, rel=1e-11)
        assert got.c == pytest.approx(p.c, rel=1e-11)


def test_the_old_method_names_still_work():
    rows = exact_prismatic_rows()
    assert C.calibrate(rows, method="seed").method == "paper"  # the name of earlier versions
    new = C.calibrate(rows, method="paper").model(3, "+").params
    assert C.calibrate(rows, method="seed").model(3, "+").params == new


def full_range_average(g0, d, alpha=0.0, beta=-1.0, start=HI, end=LO):
    return SPAN / float(steps_between(start, end, g0, d * alpha, d * beta))


@pytest.mark.parametrize("g0, d", [(41e-6, 3.83e-6), (45e-6, -8.15e-6), (47e-6, 23.94e-6), (52e-6, -19.40e-6),
                                   (41e-6, 6.91e-6), (45e-6, -10.24e-6)])
def test_fig10_d_values_recovered_from_exact_averages(g0, d):
    # Fig. 10: d- = 3.83, d+ = -8.15 (q3 = 0), 23.94, -19.40 (q3 = 12 mm), 6.91, -10.24 (theta = -pi/4) µrad
    avg = full_range_average(g0, d)
    assert C.invert_d_exact(avg, g0, HI, LO, 0.0, -1.0) == pytest.approx(d, abs=1e-12)


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(g0=st.floats(20e-6, 100e-6), d=st.floats(-40e-6, 60e-6), down=st.booleans())
def test_exact_inversion_to_1e3_urad_across_the_issue_range(g0, d, down):
    # issue 2: gamma0 in [20, 100] µrad, Delta = gamma(theta=0) - gamma0 within ±12 µrad, |error| < 1e-3 µrad
    assume(g0 + d > 0.02 * g0 and g0 - 0.5 * d > 0.02 * g0)  # step stays positive over the range (load in [-0.5, 1])
    start, end = (HI, LO) if down else (LO, HI)
    avg = full_range_average(g0, d, start=start, end=end)
    assume(abs(avg - g0) <= 12e-6)
    # only the physical branch (the one through d = 0): the average still rises with d there
    assume(full_range_average(g0, d + 1e-9, start=start, end=end) > avg)
    assert abs(C.invert_d_exact(avg, g0, start, end, 0.0, -1.0) - d) < 1e-12


def test_small_delta_slope_is_about_2_4():
    # docs/design.md: "the exact relation gives d ≈ 2.5·Δ for small Δ"; exactly 1/mean(-sin q2) = 4pi/3 / sqrt(3)
    g0, delta = 50e-6, 0.01e-6
    d = C.invert_d_exact(g0 + delta, g0, HI, LO, 0.0, -1.0)
    assert d / delta == pytest.approx((4 * math.pi / 3) / math.sqrt(3), rel=1e-3)


def test_eq9_as_printed_is_inconsistent_with_fig10():
    # Eq. 9 gives d < 1 µrad for the ±9.2 µrad the paper quotes; the exact relation gives ~22 µrad
    assert abs(float(C.eq9_printed(9.2e-6))) < 1e-6
    d_exact = C.invert_d_exact(50e-6 + 9.2e-6, 50e-6, HI, LO, 0.0, -1.0)
    assert d_exact > 20e-6


def test_seed_quadratic_comparator_error_is_several_urad():
    # the paper's grid: |Δ| <= 9.2 µrad; typical gamma0 of Fig. 6
    quad = C.fit_paper_quadratic(gamma0_values=np.linspace(30e-6, 100e-6, 5), delta_range=9.2e-6)
    # linear coefficient near the exact small-Δ slope
    assert quad.coefficients[1] == pytest.approx(2.418, abs=0.2)
    errs = []
    for g0 in (30e-6, 45e-6, 60e-6, 100e-6):
        for delta in np.linspace(-9.2e-6, 9.2e-6, 8):
            try:
                d_exact = C.invert_d_exact(g0 + delta, g0, HI, LO, 0.0, -1.0)
            except C.CalibrationError:  # unreachable: the largest average at gamma0 = 30 µrad is +6.3 µrad
                continue
            errs.append(abs(float(quad.d(delta)) - d_exact))
    assert 0.3e-6 < max(errs) < 15e-6  # an approximation: off by up to several µrad, not 1e-3


def test_seed_quadratic_step_simulation_matches_exact_grid():
    # the paper simulated step by step; the exact integral gives the same grid to < 1 step in ~1e5
    g0 = np.array([40e-6, 60e-6])
    d = np.array([10e-6, -10e-6])
    sim = _simulate_full_range_averages(g0, d, HI, LO, 0.0, -1.0)
    exact = SPAN / steps_between(HI, LO, g0, 0.0, -d)
    np.testing.assert_allclose(sim, exact, rtol=3e-5)


def test_seed_table_calibration_recovers_truth():
    cal = C.calibrate(paper_table())
    assert cal.method == "paper"
    for d in "+-":
        got, true = cal.model(2, d).params, PAPER_ROTARY[d]
        np.testing.assert_allclose(got.gamma0, true.gamma0, rtol=2e-5)  # one step in ~1e5 of rounding
        np.testing.assert_allclose(got.d, true.d, atol=0.01e-6)


def test_json_round_trip(tmp_path):
    cal = C.calibrate(paper_table())
    path = tmp_path / "cal.json"
    cal.save(path)
    data = json.loads(path.read_text())
    assert data["format"] == "stickslip.calibration" and data["day"] == "2026-11-22"
    assert {p["unit"] for p in data["parameters"]} == {"m", "rad", "1"}
    back = C.Calibration.load(path)
    assert back.parameters() == cal.parameters()
    rows = paper_table()
    np.testing.assert_array_equal(back.predict_many(rows), cal.predict_many(rows))
    assert "a+" in back.report() and "nm" in back.report()


def test_bad_calibration_files(tmp_path):
    p = tmp_path / "x.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        C.Calibration.load(p)
    p.write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="not a stickslip calibration"):
        C.Calibration.load(p)


def test_nonphysical_calibration_refused():
    # b < 0: the (0, -pi/2, 0) traverse is faster than the unloaded (-pi/2, 0, 0) one
    rows = exact_prismatic_rows(params={"+": PrismaticParams(972e-9, 0.27, 372e-9)})
    bad = [r if not (r.q2 == 0.0 and r.theta != 0.0) else
           Traverse(r.day, 3, "+", 0.0, 0.0, 0.0, r.theta, 0.0, 0.0, 0.012, 10_000) for r in rows]
    with pytest.raises(C.CalibrationError, match="non-physical"):
        C.calibrate(bad, method="paper")


def noisy_sweep(rng, n_per=40, noise=0.005):
    rows = []
    for d, p in PAPER_PRISMATIC.items():
        for pose in random_poses(rng, 3, n_per):
            rows.append(traverse_from_model(JointModel(3, d, p), pose, rng=rng, noise=noise))
    for d, p in PAPER_ROTARY.items():
        for pose in random_poses(rng, 2, n_per):
            rows.append(traverse_from_model(JointModel(2, d, p), pose, rng=rng, noise=noise))
    return rows


def test_lsq_recovers_parameters_within_standard_errors():
    rng = np.random.default_rng(11)
    rows = noisy_sweep(rng)
    cal = C.calibrate(rows)
    assert cal.method == "lsq"  # random poses: not the paper's
    z = []
    for rec in (p.to_dict() for p in cal.parameters()):
        j, d = rec["joint"], rec["direction"]
        true = (PAPER_PRISMATIC if j == 3 else PAPER_ROTARY)[d]
        names = true.names()
        idx = names.index((rec["name"], rec["q3"]))
        assert rec["stderr"] is not None and rec["stderr"] > 0
        z.append((rec["value"] - true.as_vector()[idx]) / rec["stderr"])
    assert np.max(np.abs(z)) < 4.0, z
    # and the uncertainty is honest, not huge: a+ known to better than 1 %
    a_plus = next(r for r in cal.parameters() if r.joint == 3 and r.name == "a" and r.direction == "+")
    assert a_plus.stderr is not None and a_plus.stderr / a_plus.value < 0.01


def test_lsq_refuses_undetermined_parameters():
    # every prismatic traverse unloaded and outstretched: b and c cannot be determined
    m = JointModel(3, "+", PAPER_PRISMATIC["+"])
    rows = [traverse_from_model(m, {"q2": -math.pi / 2, "theta": -math.pi / 2, "psi": p}) for p in (0.0, 0.3, -0.4)]
    with pytest.raises(C.CalibrationError, match=r"cannot determine .*b\+.*c\+|cannot determine .*c\+"):
        C.calibrate(rows, method="lsq")
    # rotary traverses all at q3 = 0: nothing fixes the 12 mm values
    mr = JointModel(2, "-", PAPER_ROTARY["-"])
    rows = [traverse_from_model(mr, {"q2": 0.0, "q3": 0.0, "theta": th, "psi": 0.0}) for th in (0.0, -0.5, -1.0, -1.5)]
    with pytest.raises(C.CalibrationError, match=r"q3 = 12 mm"):
        C.calibrate(rows, method="lsq")


def test_seed_method_requires_its_poses():
    rows = [r for r in paper_table() if not (r.joint == 3 and r.q2 == 0.0 and r.theta == 0.0)]
    with pytest.raises(C.CalibrationError, match="paper's method needs traverses at"):
        C.calibrate(rows, method="paper")
    assert C.calibrate(paper_table() + noisy_sweep(np.random.default_rng(1), 2)).method == "paper"


def test_validation_model_beats_constant_step():
    cal = C.calibrate(paper_table())
    sweep = noisy_sweep(np.random.default_rng(5), n_per=15, noise=0.01)
    res = C.validate(cal, sweep)
    for row in res.rows():
        assert row["model_max_rel_error"] < 0.05  # noise 1 %: a few sigma
        assert row["constant_max_rel_error"] > 2 * row["model_max_rel_error"]


def test_seed_quadratic_method_differs_from_exact_by_urad():
    rows = paper_table()
    exact = C.calibrate(rows, method="paper")
    quad = C.calibrate(rows, method="paper-quadratic")
    diffs = [abs(a.value - b.value) for a, b in zip(exact.parameters(), quad.parameters(), strict=True)
             if a.name == "d"]
    assert 0.05e-6 < max(diffs) < 5e-6


@pytest.mark.slow
def test_plot_draws_the_model_curves():
    import matplotlib

    matplotlib.use("Agg")
    cal = C.calibrate(paper_table())
    ax = cal.plot(3)
    line = ax.get_lines()[0]  # gamma3+ at theta = 0: Eq. 3 in nm against zeta in degrees
    z, g = line.get_data()
    p = cal.model(3, "+").params
    q2 = -np.radians(z)
    np.testing.assert_allclose(g, (1 - p.b * np.abs(np.cos(q2))) * (p.a - p.c * np.cos(-q2)) * 1e9, rtol=1e-12)
    # at zeta = 90 deg (q2 = -90 deg): no axial load, full efficiency, the step is a (Eq. 4)
    assert np.interp(90.0, z[::-1], g[::-1]) == pytest.approx(p.a * 1e9, rel=2e-3)
    assert "nm" in ax.get_ylabel() and len(ax.get_lines()) == 6
    ax2 = cal.plot(2)
    assert "µrad" in ax2.get_ylabel() and len(ax2.get_lines()) == 4
    # the direction by line style as well as colour (grey print, colour-blind readers)
    assert [ln.get_linestyle() for ln in ax2.get_lines()] == ["-", "-", "--", "--"]


def test_validation_plot_shows_relative_errors_in_percent():
    import matplotlib

    matplotlib.use("Agg")
    cal = C.calibrate(paper_table())
    res = C.validate(cal, noisy_sweep(np.random.default_rng(2), n_per=5, noise=0.01))
    ax = res.plot()
    plotted = np.concatenate([ln.get_data()[1] for ln in ax.get_lines() if len(ln.get_data()[1]) > 2])
    every_error = np.concatenate([res.model_error, res.constant_error]) * 100
    np.testing.assert_allclose(np.sort(plotted), np.sort(every_error), rtol=1e-12)
    assert "%" in ax.get_ylabel()
    assert ax.get_title() == f"validation: model against constant step, {len(res.traverses)} traverses"


def test_auto_uses_the_papers_procedure_wherever_its_poses_are():
    # joint 3 at the paper's poses, joint 2 only on a random sweep: seed for 3, least squares for 2
    rng = np.random.default_rng(8)
    prismatic = [t for t in paper_table() if t.joint == 3]
    rotary = [traverse_from_model(JointModel(2, d, p), pose, rng=rng, noise=0.003)
              for d, p in PAPER_ROTARY.items() for pose in random_poses(rng, 2, 12)]
    cal = C.calibrate(prismatic + rotary)
    assert cal.method == "paper (3+ 3-), lsq (2+ 2-)"
    seed_only = C.calibrate(prismatic)
    for d in "+-":
        assert cal.model(3, d).params == seed_only.model(3, d).params  # exactly the paper's Eqs. 4-6
        assert cal.stderr[(2, d)] is not None  # least squares, with standard errors
        np.testing.assert_allclose(cal.model(2, d).params.d, PAPER_ROTARY[d].d, atol=1.5e-6)
    back = C.Calibration.from_dict(json.loads(json.dumps(cal.to_dict())))
    assert back.method == cal.method and back.parameters() == cal.parameters()
