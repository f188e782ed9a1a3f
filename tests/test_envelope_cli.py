"""An arm already inside a keep-out margin, from the user's side: a move out is driven, a move deeper refused."""

from __future__ import annotations

import json

import pytest

from stickslip.sim.emulators import NanoControlEmulator
from test_rig_cli import _cal, run

RIG = """\
name = "bench"

[[arm]]
name = "probe"
controller = "{nano}"
calibration = "cal.json"

[[volume]]
name = "sample"  # a block whose top is 40 µm below the tip (21 mm, 0, 0) of the unreferenced arm
shape = "box"
lower = ["16mm", "-5mm", "-2.04mm"]
upper = ["26mm", "5mm", "-0.04mm"]
margin = "100um"
"""


def test_an_arm_inside_a_margin_moves_out_and_not_deeper(tmp_path):
    _cal(tmp_path / "cal.json")
    with NanoControlEmulator() as nano:
        rig = tmp_path / "rig.toml"
        rig.write_text(RIG.format(nano=nano.url), encoding="utf-8")
        common = ("--rig", rig, "--from-unreferenced", "--trust-calibration")
        r = run("rig", "check", rig)  # the pose alone: inside the margin, reported, exit 2 (a check that found one)
        assert r.exit_code == 2, r.output
        assert r.stderr.strip() == f"error: {rig}: the drawn poses break the envelope (1 problem(s) above)"
        assert "40.00 µm from 'sample', closer than the 100.00 µm allowed" in " ".join(r.output.split()), r.output
        # joint 2 down by 0.1 deg lowers the 21 mm tip by 37 µm: deeper, refused, nothing sent
        r = run("move", *common, "--joint", 2, "--by", "-0.1deg")
        assert r.exit_code == 2, r.output
        out = " ".join(r.output.split())
        assert "starts within the margin of 'sample' and the path goes deeper: 39.9" in out
        assert "move away from 'sample', or observe or reference its joints to shrink σ" in out
        assert "Traceback" not in r.output
        r = run("where", "--rig", rig, "--json")
        assert json.loads(r.stdout)["arms"][0]["q"][1] == pytest.approx(-1.5707963, abs=1e-7)
        # up by 0.5 deg raises it by 183 µm: out of the margin, driven
        r = run("move", *common, "--joint", 2, "--by", "0.5deg", "--json")
        assert r.exit_code == 0, r.output
        assert json.loads(r.stdout)["q_end_predicted"] == pytest.approx(-1.5707963 + 0.0087266, abs=1e-4)
