"""The closed loop with the image Jacobian ``camera calibrate`` measured (``--camera-calibration``).

The independent view: the peer microscope (tests/support/loop_peer.py) leaning 30 deg about
the world's y axis, its scene turned by scipy's rotation. The arm's joint 3 then moves
the tip across the image at cos 30 deg of its length, which the loop's kinematic
straight-down Jacobian does not know: the loop takes each micrometre seen for
1 / cos 30 deg of a micrometre and overshoots by about 15 %. Measured against the arm
(``camera calibrate --jacobian``, scaled by the day's true steps) the loop ends within
its tolerance. The loop itself runs with yesterday's calibration, 20 % off (as in
tests/test_closed_loop.py).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from loop_peer import open_peer, register
from typer.testing import CliRunner

from stickslip import kinematics as kin
from stickslip.cli import app
from stickslip.motion.tracking import scaled_calibration
from stickslip.vision.jacobian import (
    JACOBIAN_VERSION,
    DirectionFit,
    JacobianError,
    MeasuredJacobian,
    measured_jacobian,
)
from stickslip.vision.view import TOP_VIEW, View, base_to_image
from test_reach import DAY, true_calibration

runner = CliRunner()
DEV = f"sim://?seed=4&day={DAY}"
OFF = 1.2
TILT = 30.0
CAM = f"peercam://?pixel=1um&size=256x256&tilt={TILT:g}"


@pytest.fixture(autouse=True)
def _peercam():
    register()


@pytest.fixture()
def cals(tmp_path):
    """(today's true calibration, yesterday's with every step 20 % short), as files."""
    true = true_calibration()
    off = true
    for j in (1, 2, 3):
        off = scaled_calibration(off, j, 1.0 / OFF)
    off = dataclasses.replace(off, day="2026-11-21")
    paths = (tmp_path / "today.json", tmp_path / "yesterday.json")
    true.save(paths[0])
    off.save(paths[1])
    return str(paths[0]), str(paths[1])


def _run(args: list[str]):
    return runner.invoke(app, args)


class _At:
    """The simulator's joints as ``where`` keeps them (each command starts the simulator there)."""

    def __init__(self, q: list[float]):
        self.q = q

    def position(self, j: int) -> float:
        return self.q[j - 1]


def _true_tip(camera: str) -> str:
    r = _run(["where", "-d", DEV, "--json"])
    assert r.exit_code == 0, r.output
    q = [j["q"] for j in sorted(json.loads(r.stdout)["joints"], key=lambda j: j["joint"])]
    x, y = open_peer(camera, _At(q)).true_tip()
    return f"{x},{y}"


def _move(cal: str, extra: list[str]) -> dict:
    r = _run(["move", "-d", DEV, "-c", cal, "--joint", "3", "--by", "40um", "--camera", CAM, "--camera-tip",
              _true_tip(CAM), "--json", *extra])
    assert r.exit_code in (0, 2), r.output
    return json.loads(r.stdout)["camera"]


def test_a_tilted_microscope_misleads_the_kinematic_loop_and_not_the_measured_one(cals, tmp_path, monkeypatch):
    today, yesterday = cals
    # the kinematic Jacobian (straight down): joint 3 seen at cos 30 deg of its length
    blind = _move(yesterday, [])
    q3_blind = blind["sim_true"]["q"][2]
    assert blind["reached"]  # by its own reckoning: the seen tip within 1 px of where it thinks the target is
    assert q3_blind == pytest.approx(40e-6 / math.cos(math.radians(TILT)), rel=0.03)  # about 46 µm: 6 µm over
    assert blind["sim_true"]["error"] > 4.5e-6
    # measured against the arm, right after the day's calibration, in another database
    monkeypatch.setenv("STICKSLIP_DB", str(tmp_path / "measured.db"))
    jac = tmp_path / "jac.json"
    r = _run(["camera", "calibrate", "-d", DEV, "--camera", CAM, "--tip", _true_tip(CAM), "--joints", "3",
              "--max-steps", "40", "-c", today, "--jacobian", str(jac), "--json"])
    assert r.exit_code == 0, r.output
    vs = json.loads(r.stdout)["jacobian"]["against_view"]["3"]  # against straight down: shortened, not turned
    assert vs["length_ratio"] == pytest.approx(math.cos(math.radians(TILT)), abs=0.01) and vs["angle_deg"] < 0.5
    stored = json.loads(jac.read_text())
    assert stored["version"] == JACOBIAN_VERSION and stored["camera"] == CAM and stored["device"] == "sim://?seed=4"
    assert [(d["joint"], d["direction"]) for d in stored["directions"]] == [(3, "+"), (3, "-")]
    for d in stored["directions"]:  # px per m of joint 3: cos 30 deg of 1 px per µm, along +x either way
        assert d["px_per_unit"][0] == pytest.approx(math.cos(math.radians(TILT)) * 1e6, rel=0.02)
        assert abs(d["px_per_unit"][1]) < 0.02e6
    q_before = _where_q3()
    seen = _move(yesterday, ["--camera-calibration", str(jac)])
    assert seen["reached"] and seen["corrections"] <= 4
    assert seen["sim_true"]["error"] <= 1.25e-6  # the tolerance (1 px) and a quarter pixel of tracking
    assert seen["sim_true"]["q"][2] - q_before == pytest.approx(40e-6, abs=1e-6)
    print(f"tilt {TILT:g} deg, move 40 µm with yesterday's steps: kinematic loop true miss "
          f"{blind['sim_true']['error'] * 1e6:.2f} µm in {blind['legs']} legs; measured Jacobian "
          f"{seen['sim_true']['error'] * 1e6:.2f} µm in {seen['legs']} legs")


def _where_q3() -> float:
    r = _run(["where", "-d", DEV, "--json"])
    return float(next(j["q"] for j in json.loads(r.stdout)["joints"] if j["joint"] == 3))


# ---------------------------------------------------------------- the file and its seams


def _fits(G: np.ndarray, gammas: dict[int, float], joints=(1, 3)) -> list[DirectionFit]:
    """Noise-free fits of an image Jacobian ``G`` (px per rad or m): +n steps out, -n back."""
    out = []
    for j in joints:
        col = G[:, j - 1] * gammas[j]
        for d, sign in (("+", 1.0), ("-", -1.0)):
            steps = (0, 20, 40)
            pts = [(100.0 + sign * col[0] * n, 50.0 + sign * col[1] * n) for n in steps]
            out.append(DirectionFit(j, d, steps, np.array(pts), sign * col, 0.01, np.zeros(3)))
    return out


def _measured(view: View, pose: kin.Pose, joints=(1, 3)) -> MeasuredJacobian:
    true = true_calibration()
    A = base_to_image(view, 1e-6, pose.theta, pose.psi)
    G = A @ kin.jacobian((pose.q1, pose.q2, pose.q3))
    # the model's mean step over each fit (measured_jacobian's own gammas): what the camera saw per step
    probe = measured_jacobian(_fits(G, dict.fromkeys(joints, 1.0), joints), pose, (100.0, 50.0), true, CAM, 1e-6)
    gam = {d.joint: d.gamma for d in probe.directions if d.direction == "+"}
    fits = [f if f.direction == "+" else dataclasses.replace(f, jacobian=f.jacobian / gam[f.joint] * next(
        d.gamma for d in probe.directions if d.joint == f.joint and d.direction == "-")) for f in
        _fits(G, gam, joints)]
    return measured_jacobian(fits, pose, (100.0, 50.0), true, "peercam://?pixel=1um&password=hunter2", 1e-6)


POSE = kin.Pose(0.3, -0.4, 2e-3)


def test_the_measured_columns_give_the_tilted_camera_at_every_pose():
    view = View(math.radians(25.0), math.radians(40.0), math.radians(-10.0))
    m = _measured(view, POSE, joints=(1, 2, 3))
    for j, col in m.px_per_unit().items():  # px per unit: the camera's own columns at the pose
        want = base_to_image(view, 1e-6) @ kin.jacobian((POSE.q1, POSE.q2, POSE.q3))[:, j - 1]
        np.testing.assert_allclose(col, want, rtol=1e-9)
    A = m.image_map(base_to_image(TOP_VIEW, 1e-6))
    np.testing.assert_allclose(A, base_to_image(view, 1e-6), atol=1e-6 * 1e6)  # three joints fix the camera
    for q in ((0.0, -1.0, 0.0), (0.6, 0.2, 5e-3)):  # and so its Jacobian at another pose
        np.testing.assert_allclose(A @ kin.jacobian(q), base_to_image(view, 1e-6) @ kin.jacobian(q),
                                   atol=1e-3 * np.abs(base_to_image(view, 1e-6) @ kin.jacobian(q)).max())


def test_two_joints_fix_their_columns_and_leave_the_rest_to_the_assumed_view():
    view = View(math.radians(30.0))
    m = _measured(view, POSE)
    A0 = base_to_image(TOP_VIEW, 1e-6)
    A = m.image_map(A0)
    Jc = kin.jacobian((POSE.q1, POSE.q2, POSE.q3))
    for j in (1, 3):
        np.testing.assert_allclose(A @ Jc[:, j - 1], m.px_per_unit()[j], rtol=1e-9)
    n = np.cross(Jc[:, 0], Jc[:, 2])  # the direction neither measured joint moves along: the assumed view's
    np.testing.assert_allclose(A @ n, A0 @ n, atol=1e-6 * np.abs(A0).max())


def test_the_file_round_trips_and_keeps_no_secret(tmp_path):
    m = _measured(View(math.radians(30.0)), POSE)
    p = tmp_path / "jac.json"
    m.save(p)
    assert "hunter2" not in p.read_text()
    back = MeasuredJacobian.load(p)
    assert back == m
    assert json.loads(p.read_text())["version"] == JACOBIAN_VERSION


def test_a_file_of_another_camera_or_pixel_is_refused_in_one_line():
    m = _measured(View(math.radians(30.0)), POSE)
    m.check_camera("peercam://?pixel=1um&password=other", 1e-6)  # the same camera (secrets aside)
    with pytest.raises(JacobianError, match=r"measured with peercam://\?pixel=1um&password=\*\*\*, not simcam://"):
        m.check_camera("simcam://?pixel=1um", 1e-6)
    with pytest.raises(JacobianError, match="pixel is 1 µm, the camera's 0.5 µm"):
        m.check_camera("peercam://?pixel=1um&password=x", 0.5e-6)
    with pytest.raises(JacobianError, match="the camera's unknown"):
        m.check_camera("peercam://?pixel=1um&password=y", None)
    m.check_base(POSE._replace(q1=1.0, theta=math.radians(0.05)))  # the joints may move; the base may not turn
    with pytest.raises(JacobianError, match="base's theta at 0 deg, the arm's is 5 deg"):
        m.check_base(POSE._replace(theta=math.radians(5.0)))


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda d: d.update(version=JACOBIAN_VERSION + 1), "newer than this stickslip reads"),
        (lambda d: d.update(kind="calibration"), "not an image Jacobian"),
        (lambda d: d["directions"][0].update(gamma=0), "directions[0].gamma must be > 0"),
        (lambda d: d["directions"][0].update(px_per_step=[0, 0]), "did not move the tip"),
        (lambda d: d["directions"][1].update(joint=1, direction="+"), "given twice"),
        (lambda d: d.update(pixel_size_m=-1e-6), "pixel_size_m must be > 0"),
        (lambda d: d.update(pixel_size_m=float("nan")), "NaN/Infinity are not numbers"),
        (lambda d: d.update(tip_px="1,2"), "tip_px must be a pair of numbers"),
        (lambda d: d["pose"].pop("q3"), "pose must have"),
        (lambda d: d.update(directions=[]), "non-empty list"),
        # found by tests/test_fuzz_files.py: each was read, and the loop would have divided by it
        (lambda d: d["directions"][0].update(gamma=1e-320), "gives inf px per m or rad"),
        (lambda d: d["directions"][0].update(px_per_step=[1e308, 1e308], gamma=1e-6), "gives inf px per m"),
        (lambda d: d["directions"][0].update(px_per_step=[1e-320, 0.0]), "not a usable number"),
        (lambda d: d["directions"][0].update(px_per_step_sd=-0.1), "px_per_step_sd must be >= 0"),
        (lambda d: d["directions"][0].update(residual_px=-1.0), "residual_px must be >= 0"),
        (lambda d: d.update(pixel_size_m=10**340), "pixel_size_m must be a finite number, got an integer beyond"),
    ],
)
def test_a_bad_file_is_one_line(tmp_path, edit, words):
    m = _measured(View(math.radians(30.0)), POSE)
    d = m.to_dict()
    edit(d)
    p = tmp_path / "jac.json"
    p.write_text(json.dumps(d))
    with pytest.raises(JacobianError, match=None) as e:
        MeasuredJacobian.load(p)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_the_options_refuse_a_wrong_file_before_anything_moves(cals, tmp_path):
    _, yesterday = cals
    p = tmp_path / "jac.json"
    _measured(View(math.radians(30.0)), POSE).save(p)
    r = _run(["move", "-d", DEV, "-c", yesterday, "--joint", "3", "--by", "40um", "--camera-calibration", str(p)])
    assert r.exit_code == 2 and "--camera-calibration goes with --camera" in r.output
    r = _run(["move", "-d", DEV, "-c", yesterday, "--joint", "3", "--by", "40um", "--camera", CAM,
              "--camera-tip", "150,128", "--camera-calibration", str(p)])
    assert r.exit_code == 2 and "the camera calibration was measured with peercam://?pixel=1um&password=***" in r.output
    assert len(r.output.strip().splitlines()) == 1
    r = _run(["reach", "-d", DEV, "-c", yesterday, "--by", "0,10um,0", "--camera", CAM, "--camera-tip", "150,128",
              "--camera-calibration", str(tmp_path / "missing.json")])
    assert r.exit_code == 2 and "no such camera calibration file" in r.output
    today, _ = cals
    r = _run(["camera", "calibrate", "-d", DEV, "--camera", CAM, "--tip", "150,128", "-c", today])
    assert r.exit_code == 2 and "--calibration goes with --jacobian" in r.output
    r = _run(["camera", "calibrate", "-d", DEV, "--camera", CAM, "--tip", "150,128", "-c", today, "--jacobian",
              str(tmp_path)])
    assert r.exit_code == 2 and "not a file" in r.output
    r = _run(["where", "-d", DEV, "--json"])  # nothing moved
    assert all(j["q"] == pytest.approx(q) for j, q in zip(sorted(json.loads(r.stdout)["joints"],
                                                                  key=lambda j: j["joint"]),
                                                           (0.0, -math.pi / 2, 0.0), strict=True))


def test_a_file_measured_on_another_arm_is_refused_before_anything_moves(cals, tmp_path):
    # the file kept the camera and its pixel size, not the arm: a Jacobian measured on one arm was used on another
    # arm under the same camera URL (audit36's question); a file without a device (written before) is not checked
    _, yesterday = cals
    theirs = dataclasses.replace(_measured(View(math.radians(30.0)), POSE), camera=CAM, device="sim://?seed=9")
    p = tmp_path / "theirs.json"
    theirs.save(p)
    before = _where_q3()
    r = _run(["move", "-d", DEV, "-c", yesterday, "--joint", "3", "--by", "40um", "--camera", CAM, "--camera-tip",
              _true_tip(CAM), "--camera-calibration", str(p)])
    assert r.exit_code == 2 and _where_q3() == before
    assert "measured on sim://?seed=9, not on sim://?seed=4" in " ".join(r.stderr.split())
    dataclasses.replace(theirs, device="").save(p)  # a file of before: read as it was
    assert MeasuredJacobian.load(p).device == ""
