"""``stickslip camera``: the locate contract, calibration on sim:// with simcam://, bad inputs (exit 2, one line)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from stickslip.cli import app
from stickslip.measurements import read_step_sizes

PIL = pytest.importorskip("PIL.Image")
tifffile = pytest.importorskip("tifffile")
runner = CliRunner()
CAM = "simcam://?pixel=0.5um&photons=200"


def _ok(args: list[str]):
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    return r


def _bad(args: list[str], words: str) -> None:
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit)
    lines = r.output.splitlines()  # one line: no blank line either (a progress bar's close once added one)
    assert len(lines) == 1 and lines[0].startswith("error:") and words in r.output, repr(r.output)


@pytest.fixture()
def frames(tmp_path):
    """Three frames of the simulated microscope with the arm moved between them, and the true tips."""
    tips = []
    for k, (q3, q1) in enumerate(((0.0, 0.0), (5e-6, 5e-4), (12e-6, -3e-4))):
        _ok(["where", "-d", "sim://", "--set", f"3={q3}m", "--set", f"1={q1}rad"])  # every value with its unit
        r = _ok(["camera", "grab", "-d", "sim://", "--camera", CAM, "-o", str(tmp_path / f"f{k}.png"), "--json"])
        tips.append(json.loads(r.stdout)["sim_true_tip"])
    return tmp_path, tips


def test_locate_json_is_one_object_per_frame_in_order(frames):
    folder, tips = frames
    r = _ok(["camera", "locate", str(folder / "f*.png"), "--tip", f"{tips[0][0]},{tips[0][1]}", "--json"])
    out = json.loads(r.stdout)
    assert [o["frame"] for o in out] == [str(folder / f"f{k}.png") for k in range(3)]
    assert all(set(o) == {"frame", "x", "y", "score"} for o in out)
    assert out[0]["score"] == 1.0
    for o, t in zip(out[1:], tips[1:], strict=True):
        assert math.hypot(o["x"] - t[0], o["y"] - t[1]) < 0.5 and 0 < o["score"] <= 1


def test_locate_says_lost_with_the_reason(frames):
    folder, tips = frames
    blank = np.full((512, 512), 30000, np.uint16)
    PIL.fromarray(blank).save(folder / "f3.png")
    r = _ok(["camera", "locate", str(folder), "--tip", f"{tips[0][0]},{tips[0][1]}", "--json"])
    last = json.loads(r.stdout)[-1]
    assert set(last) == {"frame", "lost"} and last["lost"] in ("out of the field", "occluded", "out of focus", "lost")
    table = _ok(["camera", "locate", str(folder), "--tip", f"{tips[0][0]},{tips[0][1]}"]).stdout
    assert "1 of 4 frames refused" in table


def test_bad_frames_exit_2_with_one_line_and_print_nothing(tmp_path):
    PIL.fromarray(np.zeros((40, 50), np.uint8)).save(tmp_path / "a.png")
    PIL.fromarray(np.zeros((40, 60), np.uint8)).save(tmp_path / "b.png")
    _bad(["camera", "locate", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "--tip", "10,10"], "must have one size")
    (tmp_path / "c.png").write_bytes((tmp_path / "a.png").read_bytes()[:40])
    _bad(["camera", "locate", str(tmp_path / "c.png"), "--tip", "10,10"], "not a readable image")
    (tmp_path / "empty").mkdir()
    _bad(["camera", "locate", str(tmp_path / "empty"), "--tip", "10,10"], "the folder has no image files")
    tifffile.imwrite(tmp_path / "s.tif", np.zeros((4, 40, 50), np.uint16), photometric="minisblack")
    _bad(["camera", "locate", str(tmp_path / "s.tif"), "--tip", "10,10"], "stack of 4 images")
    f = np.zeros((40, 50), np.float32)
    f[3, 4] = np.nan
    tifffile.imwrite(tmp_path / "n.tif", f)
    _bad(["camera", "locate", str(tmp_path / "n.tif"), "--tip", "10,10"], "x=4, y=3")
    _bad(["camera", "locate", str(tmp_path / "nope.png"), "--tip", "10,10"], "no such file")
    _bad(["camera", "locate", str(tmp_path / "a.png"), "--tip", "10"], "write X,Y in pixels")
    for tip in ("1_0,20", "\u0663,20"):  # float() took 1_0 for 10 and Arabic-Indic digits
        _bad(["camera", "locate", str(tmp_path / "a.png"), "--tip", tip], "write X,Y in pixels")
    _bad(["camera", "locate", str(tmp_path / "a.png"), "--tip", "NaN,20"], "the pixel must be finite")
    _bad(["camera", "locate", str(tmp_path / "a.png"), "--tip", "20,20"], "nothing stands out")


def test_a_missing_camera_exits_2_and_stores_nothing(tmp_path):
    _bad(["camera", "calibrate", "-d", "sim://", "--camera", "usb://0"], "unknown camera URL scheme")
    _bad(["camera", "calibrate", "-d", "sim://", "--camera", f"files://{tmp_path}/none*.png", "-o",
          str(tmp_path / "s.csv")], "no file matches")
    assert not (tmp_path / "s.csv").exists()
    _bad(["camera", "grab", "--camera", "simcam://?look=xray", "-o", str(tmp_path / "g.png")], "the looks")
    assert not (tmp_path / "g.png").exists()


@pytest.mark.slow
def test_calibrate_measures_joint_3_and_calibrate_takes_its_rows(tmp_path):
    out = tmp_path / "steps.csv"
    r = _ok(["camera", "calibrate", "-d", "sim://", "--camera", CAM, "--joints", "3", "--max-steps", "100",
             "--day", "2026-11-22", "-o", str(out), "--json"])
    res = json.loads(r.stdout)
    (j3,) = res["joints"]
    assert j3["refused"] is None and [s["direction"] for s in j3["step_sizes"]] == ["+", "-"]
    rows = read_step_sizes(out)
    assert [(r.joint, r.method) for r in rows] == [(3, "camera"), (3, "camera")]
    assert all(0.7e-6 < r.gamma < 1.3e-6 and r.sigma < 0.02 * r.gamma for r in rows)
    # where keeps the positions the camera saw
    where = json.loads(_ok(["where", "-d", "sim://", "--offline", "--json"]).stdout)
    assert where["joints"][2]["source"] == "dead-reckoned"
    from synth import paper_table

    from stickslip.measurements import measurements_to_csv

    (tmp_path / "m.csv").write_text(measurements_to_csv(paper_table()))
    cal = json.loads(_ok(["calibrate", str(tmp_path / "m.csv"), "--step-sizes", str(out), "--json"]).stdout)
    assert "lsq with step sizes (3+ 3-)" in cal["method"]
    _bad(["calibrate", "--step-sizes", str(out)], "may be left out only with --step-sizes and --prior")


def test_joint_2_from_above_is_refused_with_the_reason(tmp_path):
    _bad(["camera", "calibrate", "-d", "sim://", "--camera", CAM, "--joints", "2", "--tip", "307.2,256"],
         "along the camera's optical axis")


def test_locate_on_a_terminal_shows_its_bar_and_prints_the_json(frames, monkeypatch):
    """On a terminal the bar's Live points sys.stderr at a rich proxy of our console, whose stream reads
    sys.stderr at each write: the console once wrote into itself (RecursionError, megabytes of traceback)."""
    from stickslip.cli import camera as camera_cli
    from stickslip.cli._output import SafeConsole

    monkeypatch.setattr(camera_cli, "err_console", SafeConsole(stderr=True, force_terminal=True, width=80))
    folder, tips = frames
    r = runner.invoke(app, ["camera", "locate", str(folder), "--tip", f"{tips[0][0]},{tips[0][1]}", "--json"])
    assert r.exit_code == 0 and r.exception is None, repr(r.exception)
    assert [o["frame"] for o in json.loads(r.stdout)] == [str(folder / f"f{k}.png") for k in range(3)]
    assert "locating" in r.stderr and "Traceback" not in r.stderr and len(r.stderr) < 10_000
    assert "None" not in r.stderr  # the count before the frames are read: 0/?, not 0/None


@pytest.mark.parametrize(("query", "words"), [
    ("pixel=", "pixel='' is empty"),  # was taken as no pixel size at all: simcam:// drew 0.5 um pixels
    ("dof=", "dof='': cannot read"),  # the option was not named: "simcam:// cannot read '' as a number ..."
    ("tip=nan", "tip='nan': cannot read"),
    ("taper=", "taper='': cannot read"),
    ("tilt=up", "tilt='up': cannot read"),
    ("centre=1mm,x,0", "centre='x': cannot read"),
])
def test_a_simcam_option_that_cannot_be_read_is_named(tmp_path, query: str, words: str) -> None:
    _bad(["camera", "grab", "-d", "sim://", "--camera", f"simcam://?{query}", "-o", str(tmp_path / "g.png")], words)
    assert not (tmp_path / "g.png").exists()


def test_an_empty_pixel_size_is_refused_for_files_too(frames) -> None:
    folder, _ = frames
    _bad(["camera", "grab", "--camera", f"files://{folder}?pixel=", "-o", str(folder / "g.png")], "pixel='' is empty")


@pytest.mark.parametrize("name", ["g.tif", "g.jpg", "g.png.bak"])
def test_grab_refuses_a_file_name_that_is_not_a_png(tmp_path, name: str) -> None:
    """grab writes a 16-bit PNG: under a .tif or .jpg name it was written all the same (PNG data, a TIFF reader
    refuses it: 'not a TIFF file: header=b'\\x89PNG'')."""
    _bad(["camera", "grab", "-d", "sim://", "--camera", CAM, "-o", str(tmp_path / name)], "name it .png")
    assert not (tmp_path / name).exists()
    _ok(["camera", "grab", "-d", "sim://", "--camera", CAM, "-o", str(tmp_path / "G.PNG")])


@pytest.mark.parametrize(("query", "words"), [
    ("tilt=0.5", "tilt='0.5': 0.5 has no unit: did you mean 0.5deg?"),  # was 0.5 rad, 28.6 deg, silently
    ("taper=0.1", "taper='0.1': 0.1 has no unit"),
    ("tip=0.4", "tip='0.4': 0.4 has no unit: did you mean 0.4um or 0.4mm?"),
    ("pixel=5e-7", "pixel='5e-7' in 'simcam://?pixel=5e-7': 5e-7 has no unit"),
])
def test_a_bare_length_or_angle_in_a_camera_url_is_refused_as_on_the_command_line(tmp_path, query: str,
                                                                                    words: str) -> None:
    _bad(["camera", "grab", "-d", "sim://", "--camera", f"simcam://?{query}", "-o", str(tmp_path / "g.png")], words)
    assert not (tmp_path / "g.png").exists()


def test_a_bare_view_angle_is_refused_and_zero_needs_no_unit(tmp_path) -> None:
    _bad(["camera", "calibrate", "-d", "sim://", "--camera", "simcam://?pixel=1um", "--view-tilt", "0.5"],
         "--view-tilt 0.5 has no unit: did you mean 0.5deg?")
    r = CliRunner().invoke(app, ["camera", "grab", "-d", "sim://", "--camera", "simcam://?pixel=1um&tilt=0&roll=0deg",
                                 "-o", str(tmp_path / "g.png")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "g.png").exists()
