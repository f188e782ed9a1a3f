"""The typed seams between layers: parameter and provenance records, device capabilities,
the traverse session workflow, and the one way into matplotlib."""

from __future__ import annotations

import csv
import json

import pytest
from synth import paper_table

from stickslip.calibration import Calibration, Parameter, Provenance, calibrate
from stickslip.devices.base import HasMicrophone, KnowsTruePosition, PoseSettable, VirtualClock
from stickslip.devices.transport import FakeTransport
from stickslip.measurements import HEADER, read_measurements
from stickslip.procedures.session import append_row
from stickslip.sim.arm import SimulatedMM3A


def test_parameters_are_typed_records_and_serialise_as_before():
    cal = calibrate(paper_table(), method="paper")
    params = cal.parameters()
    assert all(isinstance(p, Parameter) for p in params)
    a_plus = next(p for p in params if (p.joint, p.name, p.direction) == (3, "a", "+"))
    assert a_plus.value == pytest.approx(972e-9, rel=1e-4)  # the paper's a+ (design.md §3); whole step counts round it
    assert a_plus.unit == "m" and a_plus.q3 is None and a_plus.label == "j3 a+"
    d = next(p for p in params if p.joint == 2 and p.name == "d" and p.q3)
    assert d.label == "j2 d" + d.direction + " (q3=12 mm)"
    doc = cal.to_dict()
    assert doc["parameters"][0] == params[0].to_dict()
    assert set(doc["parameters"][0]) == {"joint", "direction", "name", "q3", "value", "stderr", "unit"}
    assert Calibration.from_dict(json.loads(json.dumps(doc))).parameters() == params


def test_provenance_counts_rows_and_keeps_unknown_fields():
    rows = paper_table()
    cal = calibrate(rows, method="paper", source="day1.csv")
    p = cal.provenance
    assert (p.source, p.rows, p.rows_used) == ("day1.csv", len(rows), len(rows))
    assert p.days == tuple(sorted({t.day for t in rows})) and len(p.sha256 or "") == 64
    doc = {**p.to_dict(), "instrument_note": "stage cleaned"}
    back = Provenance.from_dict(doc)
    assert back.extra == {"instrument_note": "stage cleaned"} and back.to_dict() == doc


@pytest.mark.parametrize(
    "doc, words",
    [([1], "must be an object"), ({"rows": -1}, "provenance.rows"), ({"rows": True}, "provenance.rows"),
     ({"notes": "x"}, "provenance.notes"), ({"source": 3}, "provenance.source")],
)
def test_malformed_provenance_is_refused(doc, words):
    with pytest.raises(ValueError, match=words):
        Provenance.from_dict(doc)


def test_capabilities_are_declared_by_the_simulator_only():
    sim = SimulatedMM3A(seed=0, day="2026-11-22")
    for cap in (PoseSettable, KnowsTruePosition, VirtualClock, HasMicrophone):
        assert isinstance(sim, cap), cap.__name__
    from stickslip.devices.nanocontrol import NanoControl

    nc = NanoControl(FakeTransport([], name="fake"), query_version=False)
    for cap in (PoseSettable, KnowsTruePosition, VirtualClock, HasMicrophone):
        assert not isinstance(nc, cap), cap.__name__


def test_append_row_writes_the_header_once(tmp_path):
    rows = paper_table()[:3]
    path = tmp_path / "day.csv"
    for r in rows:
        append_row(path, r)
    with path.open(newline="") as f:
        lines = list(csv.reader(f))
    assert lines[0] == list(HEADER) and len(lines) == 4
    assert [t.steps for t in read_measurements(path)] == [r.steps for r in rows]


def test_plots_come_back_as_axes_without_a_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    from stickslip import plotting

    cal = calibrate(paper_table(), method="paper")
    ax = cal.plot(joint=3)
    assert ax.get_ylabel() == "mean step size (nm)"
    assert len(ax.get_lines()) == 2 * 3  # two directions x three tilts
    assert plotting.axes(ax) is ax
