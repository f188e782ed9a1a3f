"""Fuzz the readers through their own API: a valid file mutated deep inside, loaded, and what loads is used.

The command-line batteries (``test_fuzz_cli``, ``test_fuzz_files``, ``test_hostile``) write
documents drawn from scratch; these start from a document stickslip wrote (a tuning from the
simulator's own recording, the simulator's true calibration) and change one to three things
anywhere in it (a value of the wrong type or size, a key deleted, a list entry doubled, a value
nested one deeper). The contract: the reader returns a value, or raises its documented error
(a ``ValueError`` subclass naming the field); and a value it returns can be used (a tuning
builds a detector that hears a block, reports and writes itself back; a calibration predicts
finite steps and reports). Derandomized, a modest fixed example count each.
"""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip import kinematics as kin
from stickslip.audio.detector import detector_for
from stickslip.audio.tuningfile import Tuning, TuningFileError
from stickslip.calibration import Calibration
from stickslip.config import ConfigError, parse_config
from stickslip.rig.load import RigError, parse_rig
from stickslip.units import UnitError, parse_quantity
from test_fuzz_files import _RIG  # the documented rig example (at the top: an import inside @given nests its @givens)

READERS = settings(  # derandomized by the profile in tests/conftest.py
    max_examples=40, deadline=None, database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

#: what a hand edit or a damaged file puts where a value was
HOSTILE: list[Any] = [None, True, False, 0, -1, 1, 2**63, 10**30, 1e308, -1e308, 1e-320, 0.5, "", "x", "nan", "1e999",
                      [], {}, [1], [None], {"a": 1}, "\u202e", "\uff19", [1e308, 1e308], [0, 0], [-1, 1], "2026-11-22",
                      "+", "-", [[[[1]]]]]


def _paths(doc: Any, pre: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every place in ``doc`` (the first six entries of a list), the document itself left out."""
    out = [pre] if pre else []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*pre, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:6]):
            out += _paths(v, (*pre, i))
    return out


@st.composite
def mutated(draw: st.DrawFn, base: dict[str, Any]) -> dict[str, Any]:
    """``base`` with one to three places changed: a hostile value or any number, deleted, doubled or nested."""
    doc = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        places = _paths(doc)
        if not places:
            break
        place = draw(st.sampled_from(places))
        holder = doc
        for k in place[:-1]:
            holder = holder[k]
        key = place[-1]
        op = draw(st.sampled_from(["set"] * 5 + ["number", "delete", "double", "nest"]))
        if op == "set":
            holder[key] = copy.deepcopy(draw(st.sampled_from(HOSTILE)))
        elif op == "number":
            holder[key] = draw(st.floats(allow_nan=False, allow_infinity=False) | st.integers(-(10**20), 10**20))
        elif op == "nest":
            holder[key] = [holder[key]]
        elif op == "double" and isinstance(holder, list):
            holder.append(copy.deepcopy(holder[key]))
        else:
            del holder[key]
    return doc


# -- tunings ---------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tuning_doc() -> dict[str, Any]:
    """A template tuning of the simulator's joint 3, as ``stickslip tune`` writes it (with its self-check)."""
    from stickslip.procedures.day import simulator_tunings

    doc = simulator_tunings("sim://?seed=3", joints=(3,))[3].to_dict()
    assert doc["checks"]["false_alarms_per_hour"] >= 0  # the self-check record the report reads
    return json.loads(json.dumps(doc))


def _use_tuning(t: Tuning) -> None:
    """What the commands do with a loaded tuning: hear a block, report, write it back."""
    det = detector_for(t)
    det.feed((np.random.default_rng(0).standard_normal(9600) * 0.01).astype(np.float32))
    assert t.report()
    assert Tuning.from_dict(json.loads(json.dumps(t.to_dict()))) == t


def _load_tuning(path: Path, doc: dict[str, Any]) -> Tuning | None:
    path.write_text(json.dumps(doc), encoding="utf-8")
    try:
        return Tuning.load(path)
    except TuningFileError as e:
        assert "\n" not in str(e) and str(path) in str(e)
        return None


@pytest.mark.parametrize("value", [None, "12", [1], True, -1])
def test_a_self_check_that_is_no_record_is_refused_naming_it(tmp_path: Path, tuning_doc: dict[str, Any],
                                                             value: object) -> None:
    """The report read the self-check's numbers as numbers: a string, a list or null there was a TypeError."""
    for key in ("false_alarms_per_hour", "checked_s", "latency_median_s", "stops"):
        doc = copy.deepcopy(tuning_doc)
        doc["checks"][key] = value
        with pytest.raises(TuningFileError, match=f"checks.{key}"):
            Tuning.load(_write(tmp_path / "t.json", doc))
    doc = copy.deepcopy(tuning_doc)
    doc["checks"]["warnings"] = [value] if not isinstance(value, str) else value  # a text where a list of them goes
    with pytest.raises(TuningFileError, match="checks.warnings"):
        Tuning.load(_write(tmp_path / "t.json", doc))


def test_a_whole_number_field_that_is_infinite_is_refused_naming_it(tuning_doc: dict[str, Any]) -> None:
    """``Tuning.from_dict`` with an infinite frame raised OverflowError; a NaN one said Python's words."""
    for v in (math.inf, -math.inf, math.nan):
        doc = {**tuning_doc, "frame": v}
        with pytest.raises(TuningFileError, match="frame must be an integer"):
            Tuning.from_dict(doc)


def test_the_tuning_tune_wrote_loads_and_is_used(tmp_path: Path, tuning_doc: dict[str, Any]) -> None:
    t = _load_tuning(tmp_path / "t.json", tuning_doc)
    assert t is not None
    _use_tuning(t)


def _write(path: Path, doc: Any) -> Path:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


@READERS
@given(data=st.data())
def test_a_mutated_tuning_loads_to_one_that_works_or_is_refused(tmp_path: Path, tuning_doc: dict[str, Any],
                                                                data: st.DataObject) -> None:
    doc = data.draw(mutated(tuning_doc))
    t = _load_tuning(tmp_path / "t.json", doc)
    if t is not None:
        _use_tuning(t)


# -- calibrations ----------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def calibration_doc() -> dict[str, Any]:
    from test_reach import true_calibration

    return json.loads(json.dumps(true_calibration().to_dict()))


def _use_calibration(cal: Calibration) -> None:
    """Every step it predicts is a finite number; it reports and writes itself back."""
    pose = kin.Pose(q2=-1.5, q3=0.005)
    for j in cal.joints:
        for d in "+-":
            try:
                g, c = cal.gamma(j, d, pose), cal.constant_step(j, d)
            except KeyError:  # a direction the file does not hold
                continue
            assert math.isfinite(g) and math.isfinite(c), (j, d, g, c)
    assert cal.report()
    Calibration.from_dict(json.loads(json.dumps(cal.to_dict())))


@READERS
@given(data=st.data())
def test_a_mutated_calibration_loads_to_one_that_predicts_or_is_refused(tmp_path: Path, calibration_doc: dict[str, Any],
                                                                         data: st.DataObject) -> None:
    doc = data.draw(mutated(calibration_doc))
    p = _write(tmp_path / "c.json", doc)
    try:
        cal = Calibration.load(p)
    except ValueError as e:
        assert str(p) in str(e)
        return
    _use_calibration(cal)


def test_a_self_check_with_a_number_left_out_reports_without_it(tmp_path: Path, tuning_doc: dict[str, Any]) -> None:
    """A self-check record without its ``stops`` was a KeyError in the report; now the report leaves the line out."""
    doc = copy.deepcopy(tuning_doc)
    del doc["checks"]["stops"]
    t = _load_tuning(tmp_path / "t.json", doc)
    assert t is not None
    assert "false alarms per hour" not in t.report()
    assert "false alarms per hour" in Tuning.from_dict(tuning_doc).report()


@pytest.mark.parametrize("how", ["left out", "null"])
def test_a_calibration_without_a_day_reads_as_none_known_and_writes_back_readable(
        tmp_path: Path, calibration_doc: dict[str, Any], how: str) -> None:
    """A null day was read as the session label 'None'; a file without one loaded, but what it wrote back
    (``"day": ""``) was refused ('the session label is empty'). Now both read as no day known, written as null."""
    doc = copy.deepcopy(calibration_doc)
    if how == "null":
        doc["day"] = doc["method"] = doc["created"] = None
    else:
        del doc["day"]
    cal = Calibration.load(_write(tmp_path / "c.json", doc))
    assert cal.day == ""
    assert "None" not in (cal.day, cal.method, cal.created)
    assert "day ?" in cal.report()
    cal.save(tmp_path / "again.json")
    again = Calibration.load(tmp_path / "again.json")
    assert again.day == "" and json.loads((tmp_path / "again.json").read_text())["day"] is None


@pytest.mark.parametrize("method", ["template", "band"])
def test_a_tuning_with_some_of_the_levels_it_saw_reports_without_them(tuning_doc: dict[str, Any], method: str) -> None:
    """``stepping_db`` null beside a contrast was a TypeError in the report (each of the four is optional)."""
    doc = copy.deepcopy(tuning_doc)
    if method == "band":
        doc = {k: doc[k] for k in ("band_hz", "threshold_db", "sample_rate", "frame", "hop", "contrast_db", "margin_db",
                                   "stepping_db", "stopped_db")}
    assert "margin" in Tuning.from_dict(doc).report()
    doc["stepping_db"] = None
    t = Tuning.from_dict(doc)
    assert t.method == method and "margin" not in t.report()


# -- quantities in TOML files ----------------------------------------------------------------------------------------

def test_a_whole_number_beyond_a_float_is_refused_as_not_finite(tmp_path: Path) -> None:
    """TOML carries integers of any length: a rig's ``arm_distance = 999...`` (400 digits) raised OverflowError."""
    for v in (10**400, -(10**400)):
        with pytest.raises(UnitError, match="not a finite"):
            parse_quantity(v, "length")
    text = "\n".join(f"arm_distance = {'9' * 400}" if ln.startswith("arm_distance") else ln
                      for ln in _RIG.splitlines())
    with pytest.raises(RigError, match="arm_distance"):
        parse_rig(text, "lab.toml")
    with pytest.raises(ConfigError, match="offset"):
        parse_config(f"[geometry]\noffset = {'9' * 400}\n", tmp_path / "config.toml")


# -- the server's token file -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("content", [b"", b"\n", b"  \r\n", b"\xef\xbb\xbf", "é" * 40, b"\xff" * 40, b"a" * 5000])
def test_a_token_file_that_holds_no_token_is_refused_not_recursed_on(tmp_path: Path, content: bytes | str,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """An empty token file (a server killed between creating and writing it) recursed until RecursionError:
    it was read as no file, creating it met the file, and reading it again found it empty."""
    from stickslip.server import security
    from stickslip.server.security import load_or_create_token

    monkeypatch.setattr(security, "TOKEN_WAIT_S", 0.0)  # no other server is writing it

    p = tmp_path / "serve-token"
    p.write_bytes(content.encode() if isinstance(content, str) else content)
    with pytest.raises(ValueError, match="delete it"):
        load_or_create_token(p)
    assert p.read_bytes() == (content.encode() if isinstance(content, str) else content)  # left for the user


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="FIFOs are POSIX")
def test_a_token_path_that_is_a_pipe_is_refused_not_waited_on(tmp_path: Path) -> None:
    import os

    from stickslip.server.security import load_or_create_token

    p = tmp_path / "serve-token"
    os.mkfifo(p)
    with pytest.raises(ValueError, match="delete it"):
        load_or_create_token(p)


# -- text files: byte flips, truncation, BOM, CRLF, lines doubled or dropped, numbers replaced ------------------------

_ODD = ["\ufeff", "\r\n", "\r", "\x00", "\u202e", "\uff19", "x" * 5000, "9" * 400, ",", '"', "\n", "nan", "inf", "-",
        "1e999", "\u00e9", "\t", "#", "=", "[", "]", "'", "\\"]
_NUMBERS = ["nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "0", "-0", "", "9" * 400, "1e999", '""', "true", "[]",
            "0x10", "1_0"]


@st.composite
def mutated_text(draw: st.DrawFn, base: str) -> str:
    """``base`` with one to three changes a hand, an editor or a damaged disk makes."""
    t = base
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["flip", "flip", "insert", "truncate", "bom", "crlf", "double", "drop", "number"]))
        i = draw(st.integers(0, len(t)))
        lines = t.split("\n")
        k = draw(st.integers(0, len(lines) - 1))
        if op == "flip" and t:
            i = min(i, len(t) - 1)
            t = t[:i] + draw(st.characters(exclude_categories=["Cs"]) | st.sampled_from(_ODD)) + t[i + 1:]
        elif op == "insert":
            t = t[:i] + draw(st.sampled_from(_ODD)) + t[i:]
        elif op == "truncate":
            t = t[:i]
        elif op == "bom":
            t = "\ufeff" + t
        elif op == "crlf":
            t = t.replace("\n", "\r\n")
        elif op in ("double", "drop"):
            lines[k:k + 1] = [lines[k]] * (2 if op == "double" else 0)
            t = "\n".join(lines)
        elif op == "number":
            spots = list(re.finditer(r"[-0-9.e]+|\"[^\"]*\"", t))
            if spots:
                m = spots[draw(st.integers(0, len(spots) - 1))]
                t = t[:m.start()] + draw(st.sampled_from(_NUMBERS)) + t[m.end():]
    return t


_MEASUREMENTS = """day,joint,direction,q1,q2,q3,theta,psi,start,end,steps
2026-11-22,3,+,0,-1.5,0.005,0,0,0.001,0.002,1000
2026-11-22,2,-,0,-1.5,0.005,0,0,-1.0,-1.2,4000
2026-11-22,1,+,0.1,-1.5,0.005,0,0,0.1,0.3,4000
"""
_STEP_SIZES = """day,joint,direction,q1,q2,q3,theta,psi,gamma,sigma,steps,method
2026-11-22,3,+,0,-1.5,0.005,0,0,1e-6,1e-8,1000,traverse
2026-11-22,2,-,0,-1.5,0.005,0,0,5e-5,1e-6,4000,traverse
"""
_POSES = """joint,direction,q1,q2,q3,theta,psi,start,end
3,+,0,-1.5,0.005,0,0,,
2,-,0,-1.5,0.005,0,0,-1.0,-1.2
"""
_VIBRATION = "# sample_rate_hz=25000\ntime_s,value\n" + "".join(
    f"{i / 25000},{math.sin(i / 5):.4f}\n" for i in range(64))
_CONFIG = 'device = "sim://?seed=3"\nmax_age_days = 30\n[geometry]\noffset = "0mm"\nlength = "21mm"\n'


def _refused_or(path: Path, read: Any, errors: tuple[type[Exception], ...] = (ValueError,)) -> Any:
    """What ``read(path)`` returns, or ``None`` when it refuses with one of ``errors`` naming the file."""
    try:
        return read(path)
    except errors as e:
        assert path.name in str(e), e
        return None


def _finite(obj: Any, fields: str) -> None:
    for f in fields.split():
        assert math.isfinite(getattr(obj, f)), (f, obj)


@READERS
@given(text=mutated_text(_MEASUREMENTS))
def test_a_mutated_measurement_table_gives_usable_traverses_or_is_refused(tmp_path: Path, text: str) -> None:
    from stickslip.measurements.table import as_arrays, read_measurements

    p = tmp_path / "m.csv"
    p.write_bytes(text.encode("utf-8"))
    ts = _refused_or(p, read_measurements) or []
    for t in ts:
        _finite(t, "q1 q2 q3 theta psi start end")
        assert t.steps > 0 and t.start != t.end and t.direction in "+-", t
    if ts:
        assert np.all(np.isfinite(as_arrays(ts)["start"]))


_HISTORY = '{"format": "stickslip-history", "version": 1}\n' + "".join(
    json.dumps({"day": "2026-11-20", "joint": 3, "direction": d, "q1": 0.0, "q2": -1.0, "q3": 0.0, "theta": 0.0,
                "psi": 0.0, "start": a, "end": b, "steps": 100 + k, "how": "audio", "source": 'lab "A", run\n2',
                "measured_at": f"2026-11-20T09:3{k}:00.000000+00:00", "excluded": "cable, snagged" if k else None})
    + "\n" for k, (d, a, b) in enumerate([("+", 0.0, 0.01), ("-", 0.01, 0.0), ("+", 0.002, 0.004)]))


@READERS
@given(text=mutated_text(_HISTORY))
def test_a_mutated_history_file_gives_usable_traverses_or_is_refused(tmp_path: Path, text: str) -> None:
    """export --json's file, damaged: rows the store would take, each with a time it can keep, or a refusal."""
    import datetime as dt

    from stickslip.measurements.history_file import read_history

    p = tmp_path / "h.jsonl"
    p.write_bytes(text.encode("utf-8"))
    rows = _refused_or(p, lambda q: [r for batch in read_history(q) for r in batch]) or []
    for t, prov in rows:
        _finite(t, "q1 q2 q3 theta psi start end")
        assert t.steps > 0 and t.start != t.end and t.direction in "+-", t
        assert prov.how.strip() and (prov.excluded is None or prov.excluded.strip())
        if prov.measured_at is not None:
            assert dt.datetime.fromisoformat(prov.measured_at).utcoffset() == dt.timedelta(0)


@READERS
@given(text=mutated_text(_STEP_SIZES))
def test_a_mutated_step_size_table_gives_step_sizes_or_is_refused(tmp_path: Path, text: str) -> None:
    from stickslip.measurements.steps import read_step_sizes

    p = tmp_path / "s.csv"
    p.write_bytes(text.encode("utf-8"))
    for s in _refused_or(p, read_step_sizes) or []:
        _finite(s, "q1 q2 q3 theta psi gamma")
        assert s.gamma > 0 and s.direction in "+-", s


@READERS
@given(text=mutated_text(_POSES))
def test_a_mutated_pose_table_gives_poses_or_is_refused(tmp_path: Path, text: str) -> None:
    from stickslip.measurements.poses import read_pose_table

    p = tmp_path / "p.csv"
    p.write_bytes(text.encode("utf-8"))
    got = _refused_or(p, read_pose_table)
    for q in got[2] if got else []:
        _finite(q, "q1 q2 q3 theta psi")


@READERS
@given(text=mutated_text(_VIBRATION))
def test_a_mutated_vibration_csv_gives_finite_samples_or_is_refused(tmp_path: Path, text: str) -> None:
    from stickslip.audio.sources.files import AudioSourceError
    from stickslip.audio.sources.vibration import read_vibration, sample_rate_ok

    p = tmp_path / "v.csv"
    p.write_bytes(text.encode("utf-8"))
    got = _refused_or(p, read_vibration, (ValueError, AudioSourceError))
    if got is not None:
        samples, rate = got
        assert np.all(np.isfinite(samples)) and sample_rate_ok(rate), rate


@READERS
@given(text=mutated_text(_CONFIG))
def test_a_mutated_config_file_loads_or_is_refused(tmp_path: Path, text: str) -> None:
    from stickslip.config import load_config

    p = tmp_path / "config.toml"
    p.write_bytes(text.encode("utf-8"))
    c = _refused_or(p, load_config, (ConfigError,))
    if c is not None:
        assert c.geometry_offset is None or math.isfinite(c.geometry_offset)
        assert c.geometry_length is None or 0 < c.geometry_length <= 1
        assert c.max_age_days is None or c.max_age_days >= 0


@READERS
@given(data=st.data())
def test_a_mutated_rig_file_loads_or_is_refused(tmp_path: Path, data: st.DataObject) -> None:
    from stickslip.rig.load import load_rig

    p = tmp_path / "lab.toml"
    p.write_bytes(data.draw(mutated_text(_RIG)).encode("utf-8"))
    _refused_or(p, load_rig, (RigError,))


# -- camera URLs -----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("number", ["9" * 400, "2147483648", "0000000000009999999999999", "\u0663", "\u00b2"],
                         ids=["400 nines", "2**31", "zeros then 13 digits", "arabic-indic 3", "superscript 2"])
def test_a_camera_number_opencv_cannot_take_is_refused_naming_it(number: str) -> None:
    """``opencv://`` + 400 nines reached ``cv2.VideoCapture``, whose overload error was a traceback in the CLI."""
    from stickslip.vision.camera import open_camera
    from test_fuzz_cli import check

    with pytest.raises(ValueError, match="the camera number"):
        open_camera(f"opencv://{number}")
    check(["camera", "calibrate", "-d", "sim://", "--camera", f"opencv://{number}", "-o", "/nonexistent/x.csv"])


def test_frames_named_by_a_name_the_system_refuses_are_an_image_error(tmp_path: Path) -> None:
    """``files://`` + a 400-character name raised OSError (File name too long) from ``Path.is_dir``."""
    from stickslip.vision.camera import open_camera
    from stickslip.vision.frame import ImageError
    from test_fuzz_cli import check

    for name in ("9" * 400, f"{tmp_path}/{'x' * 300}/*.png"):
        with pytest.raises(ImageError, match="cannot look at it"):
            open_camera(f"files://{name}")
    check(["camera", "calibrate", "-d", "sim://", "--camera", f"files://{'9' * 400}", "-o", tmp_path / "x.csv"])


# -- URLs and amounts ------------------------------------------------------------------------------------------------

_TEXT = st.one_of(st.text(max_size=16), st.sampled_from(
    ["nan", "inf", "-1", "0", "1e999", "9" * 400, "\u0663", "1.5", "+3", "\uff11", "", ",", ",,", "\x00", "%00", "%ff",
     "tip", "sem", "32x32", "0.5um", "1e-30um", "8deg", "1e308deg", "21mm,0,0", "nan,0,0", "0mm,21mm", "pi/0"]))
_DEVICE_KEYS = ["password", "axes", "timeout", "delay", "baud", "channels", "dialect", "ack", "hz", "profile", "margin",
                "finewithcoarse", "x"]
_SIM_KEYS = ["seed", "day", "noise", "drift", "rate", "gain_db", "physics", "warmup", "realtime", "speed", "x"]
_SIMCAM_KEYS = ["look", "seed", "pixel", "photons", "dof", "defocus", "blur", "tip", "taper", "drift", "debris", "tilt",
                "azimuth", "roll", "centre", "geometry"]


@READERS
@given(options=st.lists(st.tuples(st.sampled_from(_DEVICE_KEYS), _TEXT), max_size=4),
       scheme=st.sampled_from(["anc300", "mm3a", "mcs", "mcs2", "mm3a+socket", "sim", "nope"]),
       host=_TEXT | st.sampled_from(["h:7230", "[::1]:80", "[::1", "h:0", "h:99999", "/dev/ttyUSB0"]))
def test_a_device_urls_options_are_read_or_refused_before_anything_opens(options: list[tuple[str, str]], scheme: str,
                                                                         host: str) -> None:
    from urllib.parse import urlencode

    from stickslip.devices import base
    from stickslip.devices.anc300 import _parse_axes
    from stickslip.devices.nanocontrol import _url_settings
    from stickslip.devices.smaract._common import parse_channels

    url = f"{scheme}://{host}?{urlencode(options)}"
    for read in (base.check_device_url, base.device_key, base.redact_url, _url_settings):
        try:
            read(url)
        except ValueError as e:
            assert "\n" not in str(e)
    given = dict(options)
    for key, read in (("axes", _parse_axes), ("channels", parse_channels)):
        if key in given:
            try:
                read(given[key])
            except ValueError as e:
                assert "\n" not in str(e)


@READERS
@given(options=st.lists(st.tuples(st.sampled_from(_SIM_KEYS), _TEXT), max_size=4))
def test_a_sim_url_opens_an_arm_that_steps_or_is_refused(options: list[tuple[str, str]]) -> None:
    from urllib.parse import urlencode

    from stickslip.devices.base import DeviceError
    from stickslip.sim.urls import open_url

    try:
        arm = open_url(f"sim://?{urlencode(options)}")
    except ValueError:
        return
    try:
        arm.step(3, 5)
    except DeviceError:
        pass
    finally:
        arm.close()


@READERS
@given(options=st.lists(st.tuples(st.sampled_from(_SIMCAM_KEYS), _TEXT), max_size=3, unique_by=lambda kv: kv[0]),
       other=st.tuples(st.sampled_from(["files://", "video://", "opencv://"]), _TEXT,
                       st.lists(st.sampled_from(["fps", "pixel", "width", "height"]), max_size=2), _TEXT))
def test_a_camera_url_opens_a_camera_whose_frames_are_finite_or_is_refused(
        options: list[tuple[str, str]], other: tuple[str, str, list[str], str]) -> None:
    from urllib.parse import urlencode

    from stickslip.sim.urls import open_url
    from stickslip.vision.camera import CameraError, open_camera

    arm = open_url("sim://?seed=3")
    try:
        cam = open_camera(f"simcam://?{urlencode([('size', '48x48'), *options])}", arm)
    except (ValueError, CameraError):
        cam = None
    if cam is not None:
        try:
            assert np.all(np.isfinite(np.asarray(cam.grab().image, dtype=float)))
        except (ValueError, CameraError):
            pass
        cam.close()
    scheme, where, keys, value = other
    try:
        open_camera(f"{scheme}{where}?{urlencode([(k, value) for k in keys])}").close()
    except (ValueError, CameraError):
        pass


@READERS
@given(value=_TEXT, kind=st.sampled_from(["length", "angle"]))
def test_an_amount_is_a_finite_number_or_a_unit_error(value: str, kind: str) -> None:
    import typer

    from stickslip.cli.taskspace import parse_geometry, parse_point
    from stickslip.units import parse_typed

    for read in (parse_quantity, parse_typed):
        try:
            assert math.isfinite(read(value, kind))
        except UnitError:
            pass
    try:
        assert all(math.isfinite(v) for v in parse_point(f"{value},{value},0", "--tip"))
    except typer.Exit:
        pass
    try:
        g = parse_geometry(f"{value},{value}")
        assert math.isfinite(g.offset) and 0 < g.length <= 1, g
    except (typer.Exit, ValueError):
        pass


@pytest.fixture(scope="module")
def calibration_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from test_reach import true_calibration

    p = tmp_path_factory.mktemp("cal") / "cal.json"
    true_calibration().save(p)
    return p


@READERS
@given(value=_TEXT | st.builds(lambda n, u: f"{n}{u}", st.floats(), st.sampled_from(["um", "mm", "deg", "rad"])),
       joint=st.sampled_from(["1", "2", "3"]))
def test_amounts_reach_the_commands_with_a_calibration_that_works(tmp_path: Path, calibration_file: Path, value: str,
                                                                  joint: str) -> None:
    """The CLI battery moves with a missing calibration, so --by stops at the file; here it reaches the move."""
    from test_fuzz_cli import check

    db, cal = tmp_path / "s.db", calibration_file
    check(["move", "-d", "sim://", "-c", cal, "-j", joint, "--by", value, "--db", db])
    check(["move", "-d", "sim://", "-c", cal, "-j", joint, "--to", value, "--db", db])
    check(["observe", "-d", "sim://", "-j", joint, "--at", value, "--db", db])
    check(["reach", "-d", "sim://", "-c", cal, "--to", f"{value},0,0", "--db", db])
    check(["reach", "-d", "sim://", "-c", cal, "--by", f"0,{value},{value}", "--db", db])


# -- the kept step-scale state (a joint's track in the store) --------------------------------------------------------

_TRACK = {"log_scale": [0.0, 0.0], "P": [[7e-06, 4e-04, 2e-04], [4e-04, 0.0229, 0.01145], [2e-04, 0.01145, 0.0229]],
          "calibration": "2026-11-22|paper|2026-12-01T00:41:59+00:00", "pose": [0.0, 0.0, 9.73e-06, 0.0, 0.0]}
_RAW = ("could not convert", "float() argument", "NoneType", "setting an array", "int too large", "inhomogeneous")


@pytest.mark.parametrize(("key", "value", "named"), [
    ("pose", [0.0, 0.0, 9.73e-06, None, 0.0], "'pose'"), ("pose", [0, 0, 0, "\u202e", 0], "'pose'"),
    ("log_scale", [10**400, 0], "'log_scale'"), ("P", [[1, 2], [3]], "'P'"), ("P", None, "'P'"),
    ("log_scale", "<delete>", "no 'log_scale'"), ("<whole>", [1, 2], "not an object")])
def test_a_kept_track_that_is_no_track_is_refused_in_words(tmp_path: Path, calibration_file: Path, key: str,
                                                            value: object, named: str) -> None:
    """A hand-edited (or damaged) track said Python's words ('float() argument must be ... not NoneType') or, for an
    integer of 400 digits, raised OverflowError; each is now refused naming the field, in move's one error line."""
    import sqlite3

    from stickslip.cli import app
    from stickslip.motion.tracking import JointTrack
    from test_fuzz_cli import check, runner

    raw: Any = copy.deepcopy(_TRACK)
    if key == "<whole>":
        raw = value
    elif value == "<delete>":
        del raw[key]
    else:
        raw[key] = value
    with pytest.raises(ValueError, match=re.escape(named)) as e:
        JointTrack.from_json(raw)
    assert not any(w in str(e.value) for w in _RAW), e.value
    db = tmp_path / "s.db"
    assert runner.invoke(app, ["move", "-d", "sim://", "-c", calibration_file, "-j", "3", "--by", "10um",
                               "--db", db]).exit_code == 0
    con = sqlite3.connect(db)
    (text,) = con.execute("select value from device_state where key = 'positions'").fetchone()
    state = json.loads(text)
    state["track"]["3"] = raw
    con.execute("update device_state set value = ? where key = 'positions'", (json.dumps(state),))
    con.commit()
    con.close()
    check(["move", "-d", "sim://", "-c", calibration_file, "-j", "3", "--by", "1um", "--db", db])


@pytest.mark.parametrize("P", [[[0, 1e10, 0], [1e10, 0, 0], [0, 0, 0]],
                               [[1e308, 1e308, 0], [1e308, 1e308, 0], [0, 0, 1]]],
                         ids=["tiny variances, huge covariance", "entries near the float's end"])
def test_a_kept_covariance_beyond_a_float_is_refused_without_a_warning(P: list[list[float]]) -> None:
    """Normalising it overflowed: 'RuntimeWarning: overflow encountered in divide' printed above move's error line."""
    import warnings

    from stickslip.motion.tracking import JointTrack

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="not a valid"):
            JointTrack.from_json({**_TRACK, "P": P})


@pytest.mark.parametrize(("where", "value", "said"), [
    ("parameters[0]", None, "parameters[0] must be an object, got null"),
    ("parameters", {"a": 1}, "parameters must be a list, got an object"),
    ("provenance", [1], "provenance must be an object, got a list"),
    ("conditions", "x", "conditions must be an object, got a text"),
])
def test_a_calibration_field_of_the_wrong_kind_is_named_in_jsons_words(tmp_path: Path, calibration_doc: dict[str, Any],
                                                                        where: str, value: object, said: str) -> None:
    """'parameters[0] must be an object, got NoneType' (Python's name for null) in every command's error line."""
    from test_fuzz_cli import check

    doc = copy.deepcopy(calibration_doc)
    if where == "parameters[0]":
        doc["parameters"][0] = value
    else:
        doc[where] = value
    p = _write(tmp_path / "c.json", doc)
    with pytest.raises(ValueError, match=re.escape(said)):
        Calibration.load(p)
    check(["plan", "-c", p, "-j", "3", "--from", "0", "--to", "1um"])
