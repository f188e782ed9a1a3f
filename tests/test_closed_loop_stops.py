"""The closed loop's stopping conditions under a careless or hostile lab (audit36).

The arm is ``sim://`` with the calibration of ``test_closed_loop`` (the day's steps 20 % larger
than calibrated); the camera is the simulated microscope, 1 µm pixels, the tip at (307.2, 256).
"""

from __future__ import annotations

import json

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
