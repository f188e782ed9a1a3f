"""Fuzz what the last weeks added: check traverses, intervals, the told step rate, the server's JSON bodies.

Each kind has a regression test for what the fuzzing found (each fails on the code before its
fix: the commit says what it measured) and a bounded, derandomized hypothesis generator
(``slow``: ``make test-fast`` leaves them out) that keeps looking. They reuse
``test_fuzz_cli.check`` (one ``error:`` line, a documented exit, no traceback, nothing raw) and
``test_hostile.error_line``.

Found and mended: ``observe --sigma 1e300m`` raised OverflowError, and the server kept a measured
position of 1e297 m clamped onto the stop, an ``at_stop`` away from both stops, and ``"yes"`` as
true; a server tip target of 1e300 m answered with Python's words; a body nested 5000 deep answered
in FastAPI's shape, and on the WebSocket killed the receiver; ``int16`` samples fed to a
band detector fired a stop in the first frame; a hand-edited error model of zeros gave intervals
of zero width, and a negated covariance "math domain error"; ``calibrate --check`` with check
traverses 1000 times off wrote a calibration that could not be read back, and one listed twice counted twice.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from stickslip.audio.comparators import BandDetector
from stickslip.audio.confirm import ConfirmedStopDetector
from stickslip.audio.detector import Tuning, detector_for
from stickslip.audio.events import StopEvent
from stickslip.calibration import Calibration, CalibrationError, calibrate
from stickslip.calibration.check import CheckParams, apply_check
from stickslip.calibration.intervals import relative_sd
from stickslip.cli import app
from stickslip.joints import JOINTS
from stickslip.measurements import write_measurements
from stickslip.procedures.observe import Observation
from stickslip.sim.sound import render_traverse_recording
from test_calibration_check import DAY  # its Dahl arm day, made once when that module is collected
from test_fuzz_cli import FUZZ, check
from test_hostile import error_line

runner = CliRunner()
FEW = settings(FUZZ, max_examples=12)


@pytest.fixture(scope="module")
def kit(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A family calibration with its check (file and object), its tables, a pose table, a band tuning, sounds."""
    d = tmp_path_factory.mktemp("recent")
    write_measurements(d / "m.csv", DAY.calibration)
    write_measurements(d / "check.csv", DAY.validation)
    cal = calibrate(DAY.calibration, model="auto")
    cal.save(d / "cal.json")
    (d / "poses.csv").write_text("joint,direction,q1,q2,q3,theta,psi\n3,+,0,-1.5707963,0,0,0\n2,-,0,0,0.006,0,0\n")
    x, sr = render_traverse_recording(3, 1000.0, 0.6, 1.0, seed=21)
    return {"dir": d, "cal": cal, "cal_path": d / "cal.json", "table": d / "m.csv", "check": d / "check.csv",
            "poses": d / "poses.csv", "sound": x, "sr": sr}


# ------------------------------------------------------------------------------------- check traverses


def test_check_traverses_far_off_are_refused_not_written_unreadable(kit: dict[str, Any], tmp_path: Path) -> None:
    """Check traverses 1000 times off scaled the intervals by 1e5: the calibration was written with a
    ``sigma_model`` of 684, which every later command refused to read. Now calibrate refuses, writes nothing."""
    far = [dataclasses.replace(t, steps=t.steps * 1000) for t in DAY.validation]
    with pytest.raises(CalibrationError, match=r"joint \d: 6 check traverse\(s\) erred RMS .* would exceed 10 times"):
        apply_check(kit["cal"], far)
    write_measurements(tmp_path / "far.csv", far)
    out = tmp_path / "c.json"
    r = runner.invoke(app, ["calibrate", str(kit["table"]), "--check", str(tmp_path / "far.csv"), "-o", str(out)])
    error_line(r, "check traverse(s) erred", "joints, directions, units and step counts")
    assert not out.exists()
    slow = [dataclasses.replace(t, steps=t.steps * 2) for t in DAY.validation]  # far, but an interval still
    assert Calibration.from_dict(apply_check(kit["cal"], slow).to_dict()).predictive


def test_a_check_traverse_listed_twice_is_refused(kit: dict[str, Any], tmp_path: Path) -> None:
    """A check table appended to itself counted each traverse twice: joint 3's intervals scaled by 0.73 instead
    of 0.82 (8000 copies: 0.47), as if measured again. Now refused before anything is fitted, naming the rows."""
    twice = list(DAY.validation) + [DAY.validation[4]]
    with pytest.raises(CalibrationError, match=r"check traverse 13 repeats check traverse 5 in every column"):
        calibrate(DAY.calibration, model="auto", check=twice)
    write_measurements(tmp_path / "twice.csv", twice)
    out = tmp_path / "c.json"
    r = runner.invoke(app, ["calibrate", str(kit["table"]), "--check", str(tmp_path / "twice.csv"), "-o", str(out)])
    error_line(r, "repeats check traverse 5", "lists each traverse once")
    assert not out.exists()


def test_check_params_are_a_count() -> None:
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="prior_traverses must be a finite count"):
            CheckParams(prior_traverses=bad)
    assert CheckParams(prior_traverses=0.0).prior_traverses == 0.0


@st.composite
def check_tables(draw: st.DrawFn) -> list[Any]:
    """Check traverses: the day's validation traverses, some of the calibration's own, with steps, poses,
    joints and directions changed, repeated, or a few thousand of them."""
    pool = list(DAY.validation) + draw(st.lists(st.sampled_from(DAY.calibration), max_size=2))
    rows = draw(st.lists(st.sampled_from(pool), min_size=1, max_size=8))
    out = []
    for t in rows:
        change = draw(st.sampled_from(["none", "steps", "pose", "joint", "direction"]))
        if change == "steps":
            t = dataclasses.replace(t, steps=draw(st.sampled_from([1, 7, t.steps // 3, t.steps * 5, t.steps * 1000])))
        elif change == "pose":
            t = dataclasses.replace(t, theta=draw(st.floats(-math.pi, math.pi)), psi=draw(st.floats(-1.5, 1.5)))
        elif change == "joint" and t.joint == 2:
            t = dataclasses.replace(t, joint=1, q1=0.0, start=-0.5, end=0.5) if t.start < t.end else t
        elif change == "direction":
            t = dataclasses.replace(t, start=t.end, end=t.start, direction="-" if t.direction == "+" else "+")
        out.append(t)
    return out * draw(st.sampled_from([1, 1, 2, 300]))


@pytest.mark.slow
@FUZZ
@given(check=check_tables())
@example(check=[dataclasses.replace(t, steps=t.steps * 1000) for t in DAY.validation])  # was written unreadable
def test_a_check_is_refused_or_gives_intervals_a_file_keeps(kit: dict[str, Any], check: list[Any]) -> None:
    """Whatever the check traverses: a one-line refusal, or a calibration whose intervals are finite, positive,
    and survive a save and a load (the same predictions and the same intervals)."""
    try:
        checked = apply_check(kit["cal"], check)
    except CalibrationError as e:
        assert "\n" not in str(e)
        return
    again = Calibration.from_dict(json.loads(json.dumps(checked.to_dict())))
    for (j, d), pr in checked.predictive.items():
        cols = np.array([[0.1, -1.0, 0.003, 0.4, -0.2], [-0.4, -2.5, 0.0, -1.2, 0.9]]).T
        sd = relative_sd(checked, j, d, *cols)
        assert np.all(np.isfinite(sd)) and np.all(sd > 0), (j, d, sd)
        np.testing.assert_allclose(relative_sd(again, j, d, *cols), sd, rtol=1e-12)
        assert again.predictive[(j, d)].floor == pytest.approx(pr.floor, rel=1e-12)


@pytest.mark.slow
@FUZZ
@given(
    n=st.one_of(st.integers(-5, 25), st.sampled_from(["0", "1.5", "nan", "9" * 30, "", "-0", "2**3"])),
    seed=st.one_of(st.none(), st.integers(-3, 2**70), st.sampled_from(["-1", "1e3", "9" * 5000, "x"])),
    joint=st.sampled_from([None, "1", "2", "3", "0"]),
)
def test_suggest_check_counts_and_seeds(kit: dict[str, Any], tmp_path: Path, n: object, seed: object,
                                        joint: str | None) -> None:
    out = tmp_path / "poses.csv"
    args = ["suggest", "-c", kit["cal_path"], "--check", n, "-o", out]
    args += [] if seed is None else ["--seed", seed]
    args += [] if joint is None else ["-j", joint]
    check(args)


# ------------------------------------------------------------------------------------------ intervals


def _scaled(doc: dict[str, Any], factor: float) -> dict[str, Any]:
    """A calibration document with every error-model term multiplied by ``factor`` (a hand-edited check scale)."""
    out = copy.deepcopy(doc)
    for u in out.get("uncertainty", []):
        for k in ("floor", "slope", "drift", "drift_sd"):
            if k in u:
                u[k] = u[k] * factor
    return out


def test_an_error_model_of_zeros_is_refused(kit: dict[str, Any], tmp_path: Path) -> None:
    """A check scale of 0 (or 1e-300: its square is 0) hand-edited into the file gave 95 % intervals of zero
    width, ``gamma_pi95 = 0.0`` at every pose. The file is refused, naming the entry."""
    doc = kit["cal"].to_dict()
    for factor in (0.0, 1e-300):
        p = tmp_path / f"c{factor}.json"
        p.write_text(json.dumps(_scaled(doc, factor)))
        r = runner.invoke(app, ["predict", "-c", str(p), str(kit["poses"]), "--interval"])
        error_line(r, "uncertainty[0]", "exact prediction")
    assert Calibration.from_dict(_scaled(doc, 1e-100)).predictive  # tiny, but an interval


def test_a_covariance_that_is_no_covariance_is_refused(kit: dict[str, Any], tmp_path: Path) -> None:
    """``suggest`` inverts the parameters' covariance: a negated one ended in "error: joint 2: math domain error",
    a zero, asymmetric or indefinite one was used as it stood. The file is refused, naming the entry."""
    doc = kit["cal"].to_dict()

    def edited(f: Any) -> Path:
        out = copy.deepcopy(doc)
        c = np.array(out["uncertainty"][0]["covariance"])
        out["uncertainty"][0]["covariance"] = f(c).tolist()
        p = tmp_path / "c.json"
        p.write_text(json.dumps(out))
        return p

    d = np.sqrt(np.diag(np.array(doc["uncertainty"][0]["covariance"])))
    for f, words in ((lambda c: -c, "positive variances"), (lambda c: 0 * c, "positive variances"),
                     (lambda c: c + np.triu(np.outer(d, d), 1), "symmetric"),
                     (lambda c: np.outer(d, d) * (2 * np.eye(len(d)) - 1), "positive semi-definite")):
        error_line(runner.invoke(app, ["suggest", "-c", str(edited(f)), "--n", "1"]), "uncertainty[0].covariance",
                   words)
    r = runner.invoke(app, ["suggest", "-c", str(edited(lambda c: c * 1e6)), "--n", "1", "--json"])
    assert r.exit_code == 0, r.output  # wide is allowed: less known


@pytest.mark.slow
@FUZZ
@given(
    factor=st.sampled_from([1.0, 0.0, -1.0, 1e300, 1e-300, 1e-100, 0.5, 3.0, 1e3, math.nan, math.inf]),
    cmd=st.sampled_from(["predict", "plan"]),
    joint=st.sampled_from([2, 3]),
    q=st.sampled_from(["0", "-1.5707963", "2.0944", "2.2", "-3.6651914", "0.012", "1e-300", "nan", "inf", ""]),
    tilt=st.sampled_from(["0", "1.5707963", "-1.0471976", "3.2", "nan", "1e300"]),
)
@example(factor=0.0, cmd="predict", joint=3, q="0", tilt="0")  # gamma_pi95 0.0 at every pose
def test_intervals_at_odd_poses_and_extreme_scales(kit: dict[str, Any], tmp_path: Path, factor: float, cmd: str,
                                                    joint: int, q: str, tilt: str) -> None:
    """``predict --interval`` and ``plan`` at the edges of the load space, outside it, and on NaN, with the
    error model scaled as a hand edit would: a refusal, or an interval that is finite and not zero."""
    p = tmp_path / "c.json"
    p.write_text(json.dumps(_scaled(kit["cal"].to_dict(), factor), allow_nan=True))
    if cmd == "predict":
        poses = tmp_path / "poses.csv"
        poses.write_text(f"joint,direction,q1,q2,q3,theta,psi\n{joint},+,{q},{q},{q},{tilt},{tilt}\n")
        check(["predict", "-c", p, poses, "--interval", "-o", tmp_path / "out.csv"])
        out = tmp_path / "out.csv"
        if out.exists():
            row = out.read_text().splitlines()[1].split(",")
            half = float(row[-1])
            assert math.isfinite(half) and half > 0, row
            out.unlink()
        return
    unit = "mm" if joint == 3 else "rad"
    args = ["plan", "-c", p, "-j", joint, "--from", "0", "--to", f"{q}{unit}", "--theta", f"{tilt}rad", "--json"]
    r = runner.invoke(app, [str(a) for a in args])
    check(args)
    if r.exit_code == 0:
        plan = json.loads(r.stdout)
        assert math.isfinite(plan["pi95"]) and (plan["pi95"] > 0 or plan["steps"] == 0), plan


# ------------------------------------------------------------------------------------- audio: told rate


def test_integer_samples_are_refused_not_heard_90_db_louder(kit: dict[str, Any]) -> None:
    """int16 PCM fed to a band detector was read as samples 32768 times full scale: a stop in the first frame
    (0.008 s) of a recording with none. Every detector's feed now refuses samples that are not floats."""
    x = np.asarray(kit["sound"][: kit["sr"] // 2], dtype=np.float32)  # stepping only: no stop in it
    pcm = np.round(x * 32767).astype(np.int16)
    band = Tuning(band_hz=(5600, 7100), threshold_db=-40.0)
    assert BandDetector(band).feed(pcm.astype(np.float32) / np.float32(32768.0)) == []
    for det in (BandDetector(band), detector_for(band), ConfirmedStopDetector(detector_for(band), 0.5)):
        with pytest.raises(ValueError, match=r"float samples, got an array of int16: .*divide by 32768"):
            det.feed(pcm)
    for bad in (x > 0, x.astype(np.complex64), np.zeros((8, 2), np.float32)):
        with pytest.raises(ValueError, match="feed expects"):
            BandDetector(band).feed(bad)


@st.composite
def blocks(draw: st.DrawFn) -> np.ndarray:
    n = draw(st.sampled_from([0, 1, 2, 3, 511, 997, 2048]))
    dtype = draw(st.sampled_from(["float32", "float64", "float16", "int16", "int32", "uint8", "bool", "complex64"]))
    values = draw(st.sampled_from(["noise", "zeros", "nan", "inf", "huge", "dc"]))
    x = np.random.default_rng(n).normal(0.0, 0.1, n)
    x = {"zeros": 0 * x, "nan": np.where(x > 0, np.nan, x), "inf": np.where(x > 0.1, np.inf, x),
         "huge": x * 1e30, "dc": 0 * x + 0.5}.get(values, x)
    with np.errstate(invalid="ignore", over="ignore"):
        return x.astype(dtype)


@pytest.mark.slow
@FEW
@given(kind=st.sampled_from(["band", "template", "confirmed"]), seq=st.lists(blocks(), min_size=1, max_size=6),
       rate=st.sampled_from([None, 1000.0, 1e4, 100.0, 1e-300, 0.0, -1.0, math.nan, math.inf]))
def test_feed_any_block_and_any_told_rate(kit: dict[str, Any], kind: str, seq: list[np.ndarray],
                                          rate: float | None) -> None:
    """``feed`` with blocks of length 0, 1 and odd sizes, NaN, infinities, every dtype; ``reset`` with any told
    rate: a ValueError of one line for what is not samples or not a rate, else a list of events, never another
    exception."""
    tuning = Tuning(band_hz=(5600, 7100), threshold_db=-40.0) if kind == "band" else _tuning(kit)
    det: Any = detector_for(tuning)
    if kind == "confirmed":
        det = ConfirmedStopDetector(det, 0.2, step_clock=True, late=True)
    try:
        det.reset(0.0, rate)
    except ValueError as e:
        assert "step rate" in str(e) and "\n" not in str(e)
        return
    for b in seq:
        try:
            events = det.feed(b)
        except ValueError as e:
            assert b.dtype.kind != "f" and "feed expects float samples" in str(e), (b.dtype, e)
            continue
        assert b.dtype.kind == "f" and all(isinstance(ev, StopEvent) for ev in events)


_TUNINGS: dict[str, Tuning] = {}


def _tuning(kit: dict[str, Any]) -> Tuning:
    if "t" not in _TUNINGS:
        from stickslip.audio.tuning import tune

        _TUNINGS["t"] = tune(kit["sound"], kit["sr"], 0.6, joint=3, self_check=False, step_rate_hz=1000.0)
    return _TUNINGS["t"]


@pytest.mark.slow
@FEW
@given(rate=st.sampled_from(["1000", "0", "-5", "nan", "1e5", "10000", "100", "1", "1e400", "0.5", "x"]),
       sound=st.sampled_from(["tiny", "zeros", "dc", "clipped", "tone", "stepping"]),
       cmd=st.sampled_from(["listen", "tune"]))
def test_told_rates_on_odd_recordings(kit: dict[str, Any], tmp_path: Path, rate: str, sound: str, cmd: str) -> None:
    from stickslip.audio.sources import write_wav

    sr = kit["sr"]
    x = np.asarray(kit["sound"], dtype=np.float32)
    t = np.arange(sr) / sr
    wav = {"tiny": x[:10], "zeros": 0 * x, "dc": 0 * x + 0.5, "clipped": np.clip(x * 1000, -1, 1),
           "tone": (0.3 * np.sin(2 * np.pi * 1000.0 * t)).astype(np.float32), "stepping": x}[sound]
    path = tmp_path / f"{sound}.wav"
    write_wav(path, wav, sr)
    tuning = tmp_path / "t.json"
    _tuning(kit).save(tuning)
    if cmd == "listen":
        check(["listen", path, "--tuning", tuning, "--json", "--rate", rate])
    else:
        check(["tune", path, "--stop-at", "0.6", "--no-self-check", "-o", tmp_path / "new.json", "--rate", rate])


# -------------------------------------------------------------------------------------- observe, server


def test_a_measurement_that_cannot_be_used_is_refused(tmp_path: Path) -> None:
    """``observe --sigma 1e300m`` raised OverflowError (a traceback); a measured position outside the range, or
    'at an end stop' away from both stops, was kept (clamped onto the stop, or exact where no stop is)."""
    with pytest.raises(ValueError, match="outside joint 3's range"):
        Observation(3, 1e297)
    with pytest.raises(ValueError, match="standard deviation 1e\\+300 m is not 0 to the joint's range"):
        Observation(3, 0.001, 1e300)
    with pytest.raises(ValueError, match="at_stop: .* is not an end stop of joint 2"):
        Observation(2, math.radians(10), None, True)
    assert Observation(2, JOINTS[2].upper, None, True).sigma == 0.0
    assert Observation(3, 0.012, 0.012).sd == 0.012
    r = runner.invoke(app, ["observe", "-j", "3", "--at", "1mm", "--sigma", "1e300m", "-d", "sim://",
                            "--db", str(tmp_path / "s.db")])
    error_line(r, "standard deviation")


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    pytest.importorskip("fastapi", reason="the serve extra (fastapi) is not installed")
    from fastapi.testclient import TestClient
    from server_support import room_on

    from stickslip.server.app import create_app
    from stickslip.server.security import Access

    room = room_on(tmp_path_factory.mktemp("served"), "sim://?realtime=0")
    with TestClient(create_app(room, Access(None, True)), base_url="http://127.0.0.1:8765",
                    raise_server_exceptions=False) as c:
        yield c
    room.close()


def _refused(r: Any, *words: str) -> None:
    assert r.status_code == 422, r.text
    line = r.json()["error"]
    assert "\n" not in line and "internal error" not in line, line
    for w in words:
        assert w in line, (w, line)


def test_the_server_refuses_what_observe_and_reach_cannot_use(served: Any) -> None:
    """Before: observe with sd 1e300 answered 500 (OverflowError); q '1e300mm' answered 200 and kept 12 mm;
    at_stop 'yes' was true; a tip target 1e300 m away answered 'internal error: cannot convert float infinity'."""
    _refused(served.post("/api/observe", json={"joint": 3, "q": "1mm", "sd": 1e300}), "standard deviation")
    _refused(served.post("/api/observe", json={"joint": 3, "q": "1e300mm"}), "outside joint 3's range")
    _refused(served.post("/api/observe", json={"joint": 2, "q": "10deg", "at_stop": True}), "not an end stop")
    _refused(served.post("/api/observe", json={"joint": 2, "q": "min", "at_stop": "yes"}), "at_stop")
    _refused(served.post("/api/day", json={"resume": "true"}), "resume")
    _refused(served.post("/api/reach", json={"to": [1e300, 0, 0]}), "to[0] = 1e+300 m is not a length within 1 m")
    r = served.post("/api/observe", json={"joint": 3, "q": "max", "at_stop": True})
    assert r.status_code == 200 and r.json()["q"] == 0.012, r.text
    # an exact measurement (sd 0) is one Observation takes, from the server as from `observe --sigma 0`
    r = served.post("/api/observe", json={"joint": 3, "q": "6mm", "sd": "0um", "force": True})
    assert r.status_code == 200 and r.json()["q"] == 0.006, r.text


def test_a_body_nested_thousands_deep_and_an_unknown_path_are_one_error_line(served: Any) -> None:
    """JSON nested 5000 deep answered 400 ``{"detail": "There was an error parsing the body"}`` (FastAPI's own
    shape), an unknown path ``{"detail": "Not Found"}``; on the WebSocket such a message killed the receiver
    (RecursionError) and the socket closed without a word. Now: the documented ``{"error": one line}``."""
    from stickslip.server.live import command

    deep = "[" * 5000 + "]" * 5000
    r = served.post("/api/move", content=deep, headers={"content-type": "application/json"})
    _refused(r, "the body cannot be read as JSON (nested too deeply)")
    r = served.get("/api/nowhere")
    assert r.status_code == 404 and r.json() == {"error": "Not Found"}, r.text
    assert command(served.app.state.room, deep)["error"].startswith("a message is a JSON object")
    assert command(served.app.state.room, '{"type": "ping"}') == {"reply": "pong"}


def _mutations() -> st.SearchStrategy[object]:
    return st.one_of(
        st.none(), st.booleans(), st.integers(), st.sampled_from([10**400, 1e300, -1e-300]), st.floats(),
        st.text(max_size=12),
        st.sampled_from(["1um", "min", "max", "-pi/2", "1e300mm", "nan um", "１２µm", "\u202e3um", "0", "30deg"]),
        st.lists(st.sampled_from([0, "1um", 1e300, None]), max_size=4), st.dictionaries(st.text(max_size=3),
                                                                                         st.integers(), max_size=2),
    )


BODIES: dict[str, dict[str, object]] = {
    "/api/move": {"joint": 3, "by": "1um"},
    "/api/step": {"joint": 3, "steps": 10},
    "/api/reach": {"by": ["0um", "0um", "1um"]},
    "/api/jog": {"direction": "+x", "speed": 1},
    "/api/where": {"set": {"3": "min"}, "theta": "0deg"},
    "/api/observe": {"joint": 3, "q": "1um", "sd": "1um", "at_stop": False, "force": False},
    "/api/traverse": {"joint": 3, "direction": "+"},
    "/api/positions": {"name": "park"},
    "/api/day": {"day": "d1", "resume": False},
}


@pytest.mark.slow
@FUZZ
@given(path=st.sampled_from(sorted(BODIES)), key=st.integers(0, 4), value=_mutations(),
       how=st.sampled_from(["retype", "drop", "extra", "whole", "unicode-key"]))
@example(path="/api/observe", key=2, value=1e300, how="retype")  # sd: 500, OverflowError
@example(path="/api/observe", key=1, value="1e300mm", how="retype")  # q: 200, kept clamped onto the stop
@example(path="/api/reach", key=0, value=[1e300, 0, 0], how="retype")  # 'internal error: cannot convert ...'
def test_server_bodies_mutated(served: Any, path: str, key: int, value: object, how: str) -> None:
    """Every JSON endpoint with a body changed: a field of another type, a huge number, unicode, a field left
    out, one added, or another body altogether. Never a 500; an error is ``{"error": one line}``; a kept
    position stays within its joint's range."""
    body: object = dict(BODIES[path])
    assert isinstance(body, dict)
    name = list(body)[key % len(body)]
    if how == "retype":
        body[name] = value
    elif how == "drop":
        del body[name]
    elif how == "extra":
        body[f"{name}_"] = value
    elif how == "unicode-key":
        body = {f"{k}\u0301" if k == name else k: v for k, v in body.items()}
    else:
        body = value
    r = served.post(path, content=json.dumps(body), headers={"content-type": "application/json"})
    served.post("/api/stop")
    assert r.status_code in (200, 202, 404, 409, 422), (path, body, r.status_code, r.text)
    if r.status_code >= 400:
        line = r.json()["error"]
        assert isinstance(line, str) and "\n" not in line and "internal error" not in line, line
    elif path == "/api/observe":  # a measurement used is one within the range, not one clamped onto a stop
        assert JOINTS[3].contains(r.json()["q_measured"]), r.text
    for joint in served.get("/api/where").json()["joints"]:
        assert JOINTS[joint["joint"]].contains(joint["q"]), joint
