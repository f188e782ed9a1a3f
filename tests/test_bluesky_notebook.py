"""Notebook-friendly objects: plain and HTML reprs, tables to and from pandas, figures not shown implicitly.

Reference values: the objects' own SI fields, scaled by hand here (nm = 1e9 m,
µrad = 1e6 rad, deg = 180/pi rad), not through the display helpers under test.
"""

from __future__ import annotations

import dataclasses
import math
import sys

import pytest

from stickslip import kinematics as kin
from stickslip.calibration import Calibration, validate
from stickslip.measurements import TableError, Traverse, parse_measurements
from stickslip.measurements.dataframes import TraverseTable, from_pandas, to_pandas
from stickslip.models import PrismaticParams
from stickslip.motion.planning import plan_move
from stickslip.sim.arm import SimulatedMM3A

DAY = "2026-11-22"


def _cal() -> Calibration:
    sim = SimulatedMM3A(seed=2, day=DAY)
    models = sim.true_models()
    return Calibration(
        models=models, stderr=dict.fromkeys(models), constant_steps=dict.fromkeys(models, 9.0e-7), day=DAY,
        method="paper",
    )


def _rows() -> list[Traverse]:
    return [
        Traverse(DAY, 3, "+", 0.0, -math.pi / 2, 0.0, 0.0, 0.0, 0.0, 0.012, 12345),
        Traverse(DAY, 2, "-", 0.1, 0.0, 0.006, -math.pi / 4, 0.0, math.pi / 6, -7 * math.pi / 6, 23456),
    ]


def test_calibration_reprs() -> None:
    cal = _cal()
    # joint 3: a, b, c in + and -; joints 1, 2: gamma0, d at two q3 knots in + and -: 6 + 8 + 8
    assert repr(cal) == "Calibration(day='2026-11-22', method='paper', joints=[1, 2, 3], parameters=22, units=SI)"
    page = cal._repr_html_()
    params = cal.models[(3, "+")].params
    assert isinstance(params, PrismaticParams)
    a_plus = params.a
    assert f"<td>{a_plus * 1e9:.5g}</td>" in page  # a+ in nm
    assert page.count("<tr>") == 1 + 22
    assert "<script" not in page


def test_plan_reprs() -> None:
    cal = _cal()
    plan = plan_move(cal, 3, 0.0, 30e-6, kin.Pose())
    text = repr(plan)
    assert f"{plan.signed_steps:+d} steps" in text and "µm" in text and "nm" in text
    page = plan._repr_html_()
    assert f"<td>{plan.q_end_predicted * 1e6:.6g}</td>" in page
    down = plan_move(cal, 2, 0.0, -0.5, kin.Pose())
    assert f"<td>{down.signed_steps:+d}</td>" in down._repr_html_() and down.signed_steps < 0
    assert f"<td>{math.degrees(-0.5):.6g}</td>" in down._repr_html_()


def test_validation_reprs() -> None:
    cal = _cal()
    sim = SimulatedMM3A(seed=2, day=DAY)
    rows = []
    for t in _rows():
        true = sim.true_models()[(t.joint, t.direction)].average_gamma(t.start, t.end, t.q1, t.q2, t.q3, t.theta, t.psi)
        rows.append(dataclasses.replace(t, steps=round(abs(t.end - t.start) / float(true))))
    res = validate(cal, rows)
    assert "2 traverses" in repr(res)
    page = res._repr_html_()
    for r in res.rows():
        assert f"<td>{100 * r['model_max_rel_error']:.2f}</td>" in page


def test_traverse_table_round_trips_through_pandas_exactly() -> None:
    pytest.importorskip("pandas")
    rows = _rows()
    df = to_pandas(rows)
    assert list(df.columns)[-1] == "gamma" and df.attrs["units"]["q3"] == "m"
    assert df["gamma"].tolist() == [t.gamma for t in rows]
    assert from_pandas(df) == rows
    table = TraverseTable(rows)
    assert TraverseTable.from_pandas(table.to_pandas()) == table
    assert repr(table) == "TraverseTable(2 traverses; joints [2, 3]; days ['2026-11-22'])"
    assert f"{rows[0].gamma * 1e9:.5g} nm" in table._repr_html_()


def test_from_pandas_refuses_bad_rows_like_the_csv_reader() -> None:
    pd = pytest.importorskip("pandas")
    df = to_pandas(_rows())
    bad = df.copy()
    bad.loc[1, "steps"] = -5
    with pytest.raises(TableError) as e:
        from_pandas(bad)
    with pytest.raises(TableError) as same:
        parse_measurements(bad.drop(columns="gamma").to_csv(index=False), "<DataFrame>")
    assert e.value.problems == same.value.problems
    with pytest.raises(ValueError, match="missing column"):
        from_pandas(pd.DataFrame({"joint": [3]}))


def test_plots_return_axes_and_show_nothing() -> None:
    pytest.importorskip("matplotlib")
    ax = _cal().plot(3)
    assert ax.figure is not None
    plt = sys.modules.get("matplotlib.pyplot")
    if plt is not None:  # pyplot does not hold the figure, so a notebook does not show it at the cell's end
        assert all(plt.figure(n) is not ax.figure for n in plt.get_fignums())


def test_a_plot_of_a_joint_the_calibration_lacks_is_refused_not_drawn_empty() -> None:
    """cal.plot(1) of a calibration of joints 2 and 3 (the paper's), or plot("3"), was an empty figure titled as if
    it showed the joint; now the error use_calibration gives."""
    pytest.importorskip("matplotlib")
    full = _cal()
    cal = dataclasses.replace(full, models={k: m for k, m in full.models.items() if k[0] != 1})
    assert cal.joints == [2, 3]
    for joint in (1, "3", 3.0, True):
        with pytest.raises(ValueError, match=r"is not in this calibration \(it has joints \[2, 3\]\)"):
            cal.plot(joint)  # type: ignore[arg-type]
    assert len(cal.plot(2).lines) == 4  # each direction at q3 = 0 and 12 mm
    assert len(cal.plot(3).lines) == 6  # each direction at three tilts


@pytest.mark.slow
def test_the_python_example_in_docs_bluesky_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """docs/bluesky.md's example runs as written (docs/style.md: examples run)."""
    pytest.importorskip("bluesky")
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "bluesky.md").read_text(encoding="utf-8")
    example, tip_block = re.findall(r"```python\n(.*?)```", page, re.S)
    ns: dict[str, object] = {"__name__": "docs_bluesky"}
    exec(compile(example, "docs/bluesky.md", "exec"), ns)
    out = capsys.readouterr().out
    assert "Calibration(day=" in out
    sim = ns["sim"]
    assert isinstance(sim, SimulatedMM3A)
    assert abs(sim.position(3) - 1.5e-3) < 15e-6  # the calibrated model on the simulator: within 1 %
    assert abs(sim.position(2) + math.pi / 3) < 0.01 * (math.pi / 6)
    q3 = re.search(r"q3: ([0-9.]+) µm \(dead-reckoned\), truth ([0-9.]+) µm", out)
    assert q3 and abs(float(q3.group(1)) - 1500) < 1.0 and abs(float(q3.group(2)) - 1500) < 15  # the line as printed
    with pytest.warns(UserWarning, match="joint 1 is not in this calibration"):  # the page says a tip move warns so
        exec(compile(tip_block, "docs/bluesky.md", "exec"), ns)
    tip = re.search(r"tip \(µm\): ([-0-9.]+), ([-0-9.]+), ([-0-9.]+)", capsys.readouterr().out)
    assert tip and abs(float(tip.group(2)) - 1000) < 1.0  # y moved to 1 mm (the readback: within a step)
    assert abs(float(tip.group(3)) - 11250) < 2.0  # rel_scan put z back where it was (q2 = -60 deg, q3 = 1.5 mm)


@pytest.mark.parametrize("rows", [None, 3, "day1.csv", [1, 2], [{"joint": 3}]])
def test_notebook_tables_refuse_what_is_not_traverses_at_once(rows: object) -> None:
    """TraverseTable([1, 2]) was made, then failed in its repr with "'int' object has no attribute 'joint'"."""
    for make in (TraverseTable, to_pandas):
        with pytest.raises(TypeError, match="Traverse"):
            make(rows)  # type: ignore[arg-type]


def test_from_pandas_refuses_what_is_not_a_frame() -> None:
    with pytest.raises(TypeError, match="takes a pandas DataFrame, got list"):
        from_pandas([1, 2])
    assert TraverseTable() == [] and TraverseTable(_rows()) == _rows()
