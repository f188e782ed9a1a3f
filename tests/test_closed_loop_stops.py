"""The closed loop's stopping conditions under a careless or hostile lab (audit36).

The arm is ``sim://`` with the calibration of ``test_closed_loop`` (the day's steps 20 % larger
than calibrated); the camera is the simulated microscope, 1 µm pixels, the tip at (307.2, 256).
"""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from test_closed_loop import DEV, _run, _where, cal_off

__all__ = ["cal_off"]

CAM = "simcam://?pixel=1um"
TIP = "307.2,256"


def test_a_move_to_where_the_joint_is_reaches_without_moving(cal_off):
    # before: 'no progress: the tip is 0 µm from the target' and exit 2 (a Bluesky scan starting here failed)
    r = _run(["move", "-d", DEV, "-c", cal_off, "--joint", "3", "--to", "0um", "--camera", CAM, "--camera-tip", TIP,
              "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)["camera"]
    assert out["reached"] and out["reason"] is None and out["legs"] == 0
    assert out["sim_true"]["error"] < 1e-9
    assert _where()[3]["source"] == "default"  # nothing moved, nothing seen


def test_an_opened_camera_object_is_refused_where_a_url_is_meant():
    # before: CameraLoop(<SimCamera>) was accepted and the move failed later with AttributeError
    # ("'SimCamera' object has no attribute 'camera'") inside the Bluesky status
    from stickslip.procedures.closed_loop import CameraLoop
    from stickslip.sim.arm import SimulatedMM3A
    from stickslip.vision.camera import open_camera

    cam = open_camera(CAM, SimulatedMM3A(seed=4))
    cam.close()
    with pytest.raises(TypeError, match="camera URL .* not a SimCamera"):
        CameraLoop(cam)  # type: ignore[arg-type]
    pytest.importorskip("ophyd_async")
    from stickslip.bluesky import StickSlipAxis

    with pytest.raises(TypeError, match="camera URL or a CameraLoop, not a SimCamera"):
        StickSlipAxis(SimulatedMM3A(seed=4), 3, None, name="q3", camera=cam)  # type: ignore[arg-type]


def test_a_joint_the_camera_cannot_see_move_is_refused_before_anything_moves(cal_off):
    # joint 2 of the outstretched arm moves the tip along a straight-down camera's line of sight; before, the
    # whole move went in one leg, blind, and the loop then stopped 'the tip was lost (out of focus ...)', exit 2,
    # saying 'stopped: the seen tip 0.25 µm from the target' while the true tip was 3.3 µm off (72 µm for 1 deg)
    r = _run(["move", "-d", DEV, "-c", cal_off, "--joint", "2", "--by", "0.05deg", "--camera", CAM,
              "--camera-tip", TIP])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip() and not ln.startswith("warning:")]
    assert lines == [lines[0]] and lines[0].startswith("error: joint 2 moves the tip along the camera's line of sight")
    assert "(0% of its motion in the image" in lines[0]
    assert _where()[2]["source"] == "default"  # nothing moved


def test_unseen_problem_is_the_share_of_the_joint_motion_in_the_image():
    from stickslip import kinematics as kin
    from stickslip.procedures.closed_loop import CameraLoop, unseen_problem
    from stickslip.vision.view import View

    loop = CameraLoop(CAM)
    out = kin.Pose()  # outstretched: joint 2 moves the tip straight up
    assert unseen_problem(loop, 1, out, kin.DEFAULT_GEOMETRY) is None
    assert unseen_problem(loop, 3, out, kin.DEFAULT_GEOMETRY) is None
    assert "joint 2" in (unseen_problem(loop, 2, out, kin.DEFAULT_GEOMETRY) or "")
    # a camera leaning 60 deg about the arm's y axis sees 87 % of joint 2's motion (sin 60 deg)
    assert unseen_problem(CameraLoop(CAM, view=View(tilt=math.radians(60.0))), 2, out, kin.DEFAULT_GEOMETRY) is None
    # 15 deg: sin 15 deg = 26 % < 30 %
    assert "(26% of its motion" in (unseen_problem(CameraLoop(CAM, view=View(tilt=math.radians(15.0))), 2, out,
                                                   kin.DEFAULT_GEOMETRY) or "")


def test_a_reach_along_the_line_of_sight_is_refused_before_anything_moves(cal_off):
    # before: 'reached: the seen tip 0.44 µm from the target' though the camera saw no joint move (joint 2 alone,
    # dead-reckoned) and the true tip ended 1.56 µm off, beyond the 1 µm tolerance
    r = _run(["reach", "-d", DEV, "-c", cal_off, "--by", "0,0,-5um", "--camera", CAM, "--camera-tip", TIP])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip() and not ln.startswith("warning:")]
    assert len(lines) == 1 and lines[0].startswith("error: the tip would move along the camera's line of sight (0%")
    assert _where()[2]["source"] == "default"


def test_a_loop_that_lost_the_tip_does_not_call_its_last_position_seen(cal_off):
    # before: 'stopped: the seen tip 84.59 µm from the target' after the tip had left the field
    r = _run(["move", "-d", DEV, "-c", cal_off, "--joint", "3", "--by", "100um", "--camera",
              "simcam://?pixel=1um&size=128x128", "--camera-tip", "76.8,64"])
    assert r.exit_code == 2
    first = r.stdout.splitlines()[0]
    assert first.startswith("stopped: the tip, dead-reckoned (not seen at the last look),"), r.output
    assert "seen tip" not in r.output
    assert _where()[3]["source"] == "dead-reckoned"


class _Cropped:
    """A camera whose frames shrink by 40 px from the ``at``-th grab on (a live camera's mode changed)."""

    def __init__(self, cam, at: int):
        self.cam, self.at, self.n = cam, at, 0
        self.info = cam.info

    def grab(self):
        self.n += 1
        f = self.cam.grab()
        return dataclasses.replace(f, image=f.image[:-40, :-40]) if self.n >= self.at else f

    def close(self) -> None:
        self.cam.close()


def test_a_frame_of_another_size_mid_loop_stops_it_with_the_reason(cal_off, tmp_path):
    # before: the tracker's ValueError ('a frame of 472 x 472 px after frames of 512 x 512 px') left move_seen
    # without its result (and would end a jog session); now a stop with the reason, the joint dead-reckoned
    from stickslip.calibration import Calibration
    from stickslip.procedures.closed_loop import CameraLoop, move_seen
    from stickslip.procedures.move import MoveRequest
    from stickslip.storage import Store
    from stickslip.vision.camera import open_camera

    with Store.open(tmp_path / "s.db") as store:
        r = move_seen(store, MoveRequest(DEV, 3, by=60e-6), Calibration.load(cal_off),
                      CameraLoop(CAM, tip=(307.2, 256.0)),
                      camera_opener=lambda url, dev: _Cropped(open_camera(url, dev), 4))
    assert not r.reached and r.reason is not None
    assert r.reason.startswith("the camera failed (a frame of 472 x 472 px after frames of 512 x 512 px")
    assert len(r.looks) == 2 and r.looks[-1].pixel is None and r.looks[0].seen  # one leg seen, then the failure
    assert r.state.sources[3] == "dead-reckoned"


def test_a_camera_that_disagrees_with_the_dead_reckoning_leaves_the_joint_uncertain_over_both(tmp_path):
    # the day's steps three times the calibrated ones: the first leg's fix lies far beyond the gate (11.8 sd).
    # Before, the joint stayed dead-reckoned at 15.9 µm with sd 2.67 µm, the truth 47.7 µm (the camera's 47.6),
    # 11.9 sd away: silently wrong, and the next move planned from it
    from stickslip.motion.tracking import scaled_calibration
    from test_closed_loop import CAL_DAY
    from test_reach import true_calibration

    cal = true_calibration()
    for j in (1, 2, 3):
        cal = scaled_calibration(cal, j, 1.0 / 3.0)
    path = tmp_path / "cal-3x.json"
    dataclasses.replace(cal, day=CAL_DAY).save(path)
    r = _run(["move", "-d", DEV, "-c", str(path), "--joint", "3", "--by", "100um", "--camera", CAM,
              "--camera-tip", TIP, "--json"])
    assert r.exit_code == 2
    out = json.loads(r.stdout)["camera"]
    assert "standard deviations from its dead reckoning" in out["reason"] and "kept uncertain" in out["reason"]
    assert out["sources"]["3"] == "uncertain"
    w = _where()[3]
    assert w["source"] == "uncertain"
    lo, hi = w["uncertain"]
    true_q3 = out["sim_true"]["q"][2]
    assert lo <= w["q"] <= hi and lo <= true_q3 <= hi  # the reckoning and the truth (the camera's) both inside
    assert true_q3 - w["q"] > 10e-6  # a real disagreement, not noise
    r = _run(["move", "-d", DEV, "-c", str(path), "--joint", "3", "--by", "10um"])
    assert r.exit_code == 2 and "uncertain (the camera and the dead reckoning disagreed" in r.output


def test_a_loop_interrupted_mid_way_keeps_the_start_s_own_sd(cal_off, tmp_path):
    # the camera measures motion from the start, so a seen position is as uncertain as the start was; the loop
    # puts the start's sd back at its end. Before, Ctrl-C (or a Bluesky stop) on the third leg skipped that:
    # the open-loop move's 16.7 µm sd was kept as 0.34 µm
    from stickslip.calibration import Calibration
    from stickslip.devices.base import open_device
    from stickslip.procedures.closed_loop import CameraLoop, move_seen
    from stickslip.procedures.move import Interrupted, MoveRequest, move
    from stickslip.storage import Store

    cal = Calibration.load(cal_off)
    sim = open_device(DEV)
    calls = []
    real_step = sim.step

    def step(joint: int, n: int) -> None:
        calls.append(n)
        if len(calls) == 3:
            raise KeyboardInterrupt
        real_step(joint, n)

    sim.step = step  # type: ignore[method-assign]
    with Store.open(tmp_path / "s.db") as store:
        before = move(store, MoveRequest(DEV, 3, by=100e-6), cal).state
        sd0 = math.sqrt(before.track[3]["P"][0][0])
        assert sd0 > 10e-6
        tip = (307.2 + before.positions[3] * 1e6, 256.0)  # the simulator is placed at the kept positions
        with pytest.raises(Interrupted) as e:
            move_seen(store, MoveRequest(DEV, 3, by=60e-6), cal, CameraLoop(CAM, tip=tip), opener=lambda _url: sim)
    kept = e.value.state
    assert kept.sources[3] == "seen"  # two legs were seen before the interrupt
    assert math.sqrt(kept.track[3]["P"][0][0]) >= sd0


def test_a_bluesky_stop_while_the_tip_is_being_found_leaves_the_joint_uncertain(RE):
    # camera= a URL alone: each move first steps joint 3 out by 20 steps and back to find the tip. A stop between
    # the two was taken as 'before a burst was sent' and cleared the journal: before, joint 3 was kept at 0 µm
    # ('its dead-reckoned position is 0 µm') with the arm 19.6 µm out
    pytest.importorskip("ophyd_async")
    import bluesky.plan_stubs as bps
    from bluesky.utils import FailedStatus
    from ophyd_async.core import init_devices

    from stickslip.bluesky import StickSlipAxis
    from stickslip.calibration import Calibration
    from stickslip.sim.arm import SimulatedMM3A
    from test_reach import true_calibration

    sim = SimulatedMM3A(seed=4, day="2026-11-22")
    cal: Calibration = true_calibration()
    real_step = sim.step
    with init_devices():
        axis = StickSlipAxis(sim, 3, cal, name="q3", camera=CAM)

    def step(joint: int, n: int) -> None:
        real_step(joint, n)
        if n == 20:  # the steps out to find the tip are made: the user presses stop now
            axis._stop_event.set()

    sim.step = step  # type: ignore[method-assign]
    with pytest.raises(FailedStatus) as e:
        RE(bps.mv(axis, 40e-6))
    assert "was stepped out and back to find the tip" in str(e.value.__cause__)
    kept = axis.link.load()
    assert 3 in kept.uncertain
    lo, hi = kept.uncertain[3]
    assert lo <= sim.position(3) <= hi and sim.position(3) > 15e-6


def test_move_seen_given_a_url_string_says_what_it_takes(cal_off, tmp_path):
    # before: AttributeError "'str' object has no attribute 'jacobian'" (StickSlipAxis takes a URL, move_seen not)
    from stickslip.calibration import Calibration
    from stickslip.procedures.closed_loop import move_seen
    from stickslip.procedures.move import MoveRequest
    from stickslip.storage import Store

    with Store.open(tmp_path / "s.db") as store, pytest.raises(TypeError, match=r"CameraLoop\('simcam://"):
        move_seen(store, MoveRequest(DEV, 3, by=10e-6), Calibration.load(cal_off), CAM)  # type: ignore[arg-type]
    assert _where()[3]["source"] == "default"
    from stickslip.procedures.closed_loop import reach_seen
    from stickslip.procedures.reach import ReachRequest

    with Store.open(tmp_path / "s.db") as store, pytest.raises(TypeError, match=r"CameraLoop\('simcam://"):
        reach_seen(store, ReachRequest(DEV, by=(10e-6, 0.0, 0.0)), Calibration.load(cal_off), CAM)  # type: ignore[arg-type]


@pytest.mark.parametrize("stated", [1.0, 0.67])
def test_a_camera_stating_a_wrong_pixel_size_is_said_not_silently_reached(tmp_path, stated):
    # a camera stating 0.67 of its pixel size made the motion look 1.5x larger: the loop learnt steps x0.75 of
    # the (true, today's) calibration's and ended 'reached' with the tip at 89 µm for 60 µm, without a word
    # (audit36's question: the loop cannot tell a wrong pixel size from changed steps; it says so now)
    from stickslip.procedures.closed_loop import CameraLoop, move_seen
    from stickslip.procedures.move import MoveRequest
    from stickslip.storage import Store
    from stickslip.vision.camera import open_camera
    from test_reach import DAY, true_calibration

    class Stating:  # the frames as they are, the pixel size stated `stated` times the true one
        def __init__(self, cam):
            self.cam = cam
            self.info = dataclasses.replace(cam.info, pixel_size_m=cam.info.pixel_size_m * stated)

        def grab(self):
            return self.cam.grab()

        def close(self):
            self.cam.close()

    cal = dataclasses.replace(true_calibration(), day=DAY)  # today's: its model error (7.5 %) is what is expected
    said: list[str] = []
    with Store.open(str(tmp_path / "s.db")) as st:
        r = move_seen(st, MoveRequest(DEV, 3, by=60e-6), cal, CameraLoop(CAM, tip=(307.2, 256.0)),
                      warn=said.append, camera_opener=lambda u, dev: Stating(open_camera(u, dev)))
    scale, true_q3 = r.looks[-1].step_scale[3], r.sim_true[2]
    lines = [w for w in said if "pixel size" in w]
    assert r.reached
    if stated == 1.0:
        assert abs(true_q3 - 60e-6) < 1.5e-6 and 0.9 < scale < 1.1 and not lines
    else:
        assert true_q3 > 85e-6 and scale < 0.8  # the loop still cannot tell: the move ends far off, and says so
        assert len(lines) == 1 and lines[0].startswith("joint 3: the camera makes its steps x0.68 of the calibration")
        assert "more than 3 times the change expected (8%)" in lines[0]


@pytest.mark.slow  # seconds: in make test, out of the fast tier
def test_a_bluesky_scan_with_the_tip_given_once_follows_the_tip_from_move_to_move(RE):
    # CameraLoop(tip=...) gives the tip's pixel now; every later move started from that pixel, on the shaft by
    # then: a 5-point bp.scan from 0 to 400 µm stopped at 116 µm, 'the fit did not settle' (audit36's question)
    pytest.importorskip("ophyd_async")
    import bluesky.plan_stubs as bps
    from ophyd_async.core import init_devices

    from stickslip.bluesky import StickSlipAxis
    from stickslip.procedures.closed_loop import CameraLoop
    from stickslip.sim.arm import SimulatedMM3A
    from test_reach import true_calibration

    sim = SimulatedMM3A(seed=4, day="2026-11-22")
    with init_devices():
        axis = StickSlipAxis(sim, 3, true_calibration(), name="q3", camera=CameraLoop(CAM, tip=(307.2, 256.0)))
    for target in (40e-6, 80e-6, 120e-6):
        RE(bps.mv(axis, target))
        assert abs(sim.position(3) - target) <= 1e-6  # the true joint, within the tolerance (1 px of 1 µm)
        tip = axis.camera.tip
        assert tip is not None and math.hypot(tip[0] - (307.2 + target * 1e6), tip[1] - 256.0) < 1.5


def test_a_bluesky_stop_that_cuts_a_closed_loop_burst_short_leaves_the_joint_uncertain(RE):
    # a controller that says nothing of a burst cut short by stop() (the ANC300: its stepw answers once the axis
    # stops), not on a virtual clock: the closed loop's proxy counts the leg in full (atomic), but the look after
    # the leg sees the tip short of it, and the joint is kept uncertain over both, the true position inside (audit60:
    # what held; 8 of 16 steps made, uncertain 22.1-33.1 µm, true 23.5 µm)
    pytest.importorskip("ophyd_async")
    import bluesky.plan_stubs as bps
    from bluesky.utils import FailedStatus
    from ophyd_async.core import init_devices

    from stickslip.bluesky import StickSlipAxis
    from stickslip.procedures.closed_loop import CameraLoop
    from stickslip.sim.arm import SimulatedMM3A
    from test_reach import true_calibration

    sim = SimulatedMM3A(seed=4, day="2026-11-22")
    bursts: list[int] = []

    class CutShort:  # real time (no clock_s): a stop during its burst is not known to have come after it
        def step(self, joint: int, n: int) -> None:
            bursts.append(n)
            if len(bursts) == 2:  # stop() pressed during the second burst: half of it made, stepw answers
                axis._stop_event.set()
                sim.step(joint, n // 2)
                return
            sim.step(joint, n)

        def __getattr__(self, name: str) -> object:
            if name == "clock_s":
                raise AttributeError(name)
            return getattr(sim, name)

    with init_devices():
        axis = StickSlipAxis(CutShort(), 3, true_calibration(), name="q3", burst=200,  # type: ignore[arg-type]
                             camera=CameraLoop(CAM, tip=(307.2, 256.0)))
    with pytest.raises(FailedStatus):
        RE(bps.mv(axis, 600e-6))
    assert len(bursts) == 2 and abs(bursts[1]) > 10  # a leg of 16 steps: 8 made, 16 counted
    kept = axis.link.load()
    true_q3 = sim.position(3)
    assert 3 in kept.uncertain, (kept.positions[3], true_q3)
    lo, hi = kept.uncertain[3]
    assert lo <= true_q3 <= hi
