"""Fuzz the files the CLI fuzz battery does not reach: image frames, rig files, camera calibrations, vibration CSVs.

The same contract as ``test_fuzz_cli.py`` (whose ``check`` this reuses): an exit code in
``EXIT_CODES``, at most one ``error:`` line naming the file and the reason, no traceback,
none of Python's raw words. Derandomized and bounded (a fixed example count each).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from test_fuzz_cli import check

pytestmark = pytest.mark.slow  # make test-fast leaves this file out

FILES = settings(  # derandomized by the profile in `make test` (tests/conftest.py); `make test-explore` draws fresh
    max_examples=25, deadline=None, database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

# -- image frames for `camera locate` --------------------------------------------------------------------------------

_VALUES = [0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 1e-310, 1e-45, 1e99, -1e99, 1e100, 1.0000001e100, 1e300, -1e300,
           3.4e38, -3.4e38, float("nan"), float("inf"), float("-inf"), 65535.0, 255.0, 0.5]


def _needle(h: int, w: int, x: float, y: float, contrast: float) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    along, across = xx - x, np.abs(yy - y)
    return 0.3 + contrast * ((along >= 0) & (across <= 3 + 0.15 * along))


@st.composite
def frames(draw):
    """A base frame (needle, constant, noise), its size near MIN_SIDE or thin, then pixels set to extreme values."""
    h = draw(st.sampled_from([1, 15, 16, 17, 40, 64, 64, 64]))
    w = draw(st.sampled_from([1, 16, 17, 33, 64, 64, 64]))
    if draw(st.integers(0, 3)):  # mostly a tip well inside, else anywhere near or over the edge
        x, y = draw(st.floats(0.3, 0.7)) * w, draw(st.floats(0.3, 0.7)) * h
    else:
        x, y = draw(st.floats(-5, w + 5)), draw(st.floats(-5, h + 5))
    kind = draw(st.sampled_from(["needle", "needle", "constant", "noise"]))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    if kind == "needle":
        a = _needle(h, w, x, y, draw(st.sampled_from([0.6, -0.6, 1e-12, 1e6])))
    elif kind == "constant":
        a = np.full((h, w), draw(st.sampled_from(_VALUES)))
    else:
        a = rng.normal(0.5, 0.2, (h, w))
    scale = draw(st.sampled_from([1.0, 1e-300, 1e-310, 1e90, -1.0, 255.0, 65535.0]))
    a = a * scale
    for _ in range(draw(st.integers(0, 3))):
        a[draw(st.integers(0, h - 1)), draw(st.integers(0, w - 1))] = draw(st.sampled_from(_VALUES))
    dtype = draw(st.sampled_from(["uint8", "uint16", "float32", "float64", "int16", "int32", "rgb8", "rgb16",
                                  "rgbf64"]))
    return a, dtype, (x, y)


def _write(path, a: np.ndarray, dtype: str) -> None:
    import tifffile
    from PIL import Image

    with np.errstate(all="ignore"):
        if dtype in ("uint8", "uint16", "int16", "int32", "rgb8", "rgb16"):
            t = {"uint8": np.uint8, "uint16": np.uint16, "int16": np.int16, "int32": np.int32,
                 "rgb8": np.uint8, "rgb16": np.uint16}[dtype]
            info = np.iinfo(t)
            b = np.clip(np.nan_to_num(a, nan=0.0, posinf=info.max, neginf=info.min), info.min, info.max).astype(t)
            if dtype.startswith("rgb"):
                b = np.stack([b, b // 2, b], axis=-1)
            if dtype == "uint8" and path.suffix == ".png":
                Image.fromarray(b).save(path)
                return
            tifffile.imwrite(path, b)
            return
        if dtype == "rgbf64":
            tifffile.imwrite(path, np.stack([a, a, a * 0.5], axis=-1), photometric="rgb")
            return
        tifffile.imwrite(path, a.astype(dtype))


@FILES
@given(first=frames(), n=st.integers(1, 4), odd=st.integers(0, 3), tip=st.one_of(
    st.none(), st.sampled_from(["nan,1", "1e309,2", "-0,-0", "1,2,3", "", ",", "0x10,4", "1_0,1_0", "１,2", "inf,inf",
                                "9" * 400 + ",1", " 3 , 4 ", "-1e-320,5"])))
def test_camera_locate_frames(tmp_path, first, n, odd, tip):
    """Frames of every sample type, size and value; one of several frames differs; any --tip string."""
    a, dtype, (x, y) = first
    paths = []
    for k in range(n):
        p = tmp_path / f"f{k:02d}{'.png' if dtype == 'uint8' and k % 2 else '.tif'}"
        b = a if k != odd else np.roll(a, 3, axis=-1) * 2.0
        _write(p, b, dtype)
        paths.append(p)
    check(["camera", "locate", *paths, "--tip", tip if tip is not None else f"{x!r},{y!r}", "--json"])


def test_camera_locate_float_frames_beyond_float32_or_denormal():
    """Hand-picked edge values: float32's max, denormals, -0 and a tip on each edge of a MIN_SIDE frame."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        base = _needle(16, 16, 8.0, 8.0, 0.6)
        for scale, dtype in ((3.4e38, "float32"), (1e-320, "float64"), (1e-45, "float32"), (-0.0, "float64")):
            p = Path(d) / "a.tif"
            _write(p, base * scale, dtype)
            for tip in ("8,8", "0,0", "15,15", "-0.5,-0.5", "15.5,15.5", "16,8"):
                check(["camera", "locate", p, p, "--tip", tip])


# -- rig files -------------------------------------------------------------------------------------------------------

_RIG = """name = "fuzz"
arm_distance = "1mm"
n_sigma = 3

[stage]
tilt = "52deg"

[[arm]]
name = "probe"
kind = "mm3a"
controller = "sim://?seed=1"
radius = "0.5mm"
mount = { origin = ["-30mm", "0mm", "0mm"], rotation = ["0deg", "0deg", "0deg"] }
geometry = { offset = "0mm", length = "23.5mm" }
home = ["0deg", "-90deg", "0mm"]

[[arm]]
name = "gripper"
kind = "xyz"
controller = "sim://?seed=2"
tool = ["0mm", "0mm", "-12mm"]
axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
mount = { origin = ["30mm", "0mm", "5mm"], rotation = ["0deg", "0deg", "180deg"] }

  [[arm.joint]]
  channel = 2
  sign = -1
  range = ["-6mm", "6mm"]
  stops = ["lower", "upper"]
  step = "0.5um"

  [[arm.joint]]
  channel = 1
  range = ["-6mm", "6mm"]

  [[arm.joint]]
  channel = 3
  range = ["-6mm", "6mm"]
  soft = ["-6mm", "2mm"]

[[volume]]
name = "objective"
shape = "cylinder"
base = ["0mm", "0mm", "4mm"]
axis = [0, 0, 1]
radius = "8mm"
height = "40mm"
margin = "300um"

[[volume]]
name = "sample"
shape = "half-space"
point = ["0mm", "0mm", "-0.5mm"]
normal = [0, 0, -1]
margin = "50um"
on_stage = true

[[volume]]
name = "gas injector"
shape = "box"
lower = ["10mm", "-3mm", "2mm"]
upper = ["25mm", "3mm", "8mm"]
rotation = ["0deg", "0deg", "30deg"]

[[position]]
name = "park"
arm = "probe"
q1 = "0deg"
q2 = "-150deg"
q3 = "0mm"
order = [3, 2, 1]
"""

_RIG_VALUES = ['"0mm"', '"-5mm"', '"1e999mm"', '"nan mm"', '"inf"', "nan", "inf", "-inf", "1e308", "0", "-1",
               "true", '""', '"π"', '"probe"', "[0, 0, 0]", '["1e300m", "0m", "0m"]', '["nan", "0", "0"]',
               "[1e308, 1e308, 1e308]", "[0, 0, 1e-320]", "{}", "[]", '"\\u202e"', '"Ünïcødé 🧪"', "2**63",
               "9223372036854775808", '["0mm", "0mm"]', '["6mm", "-6mm"]', '"-0deg"', '"1e300deg"', '"20turns"',
               "[[1, 0, 0], [1, 0, 0], [0, 0, 1]]", "[1e308, 1e308, 0]"]


@st.composite
def rig_texts(draw):
    """The documented example with a line's value replaced, a line or table dropped or doubled, or lines swapped."""
    lines = _RIG.splitlines()
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["value"] * 6 + ["drop", "drop", "double", "swap"]))
        if op == "value" and "=" in lines[i]:
            key = lines[i].split("=", 1)[0]
            lines[i] = f"{key}= {draw(st.sampled_from(_RIG_VALUES))}"
        elif op == "drop":
            del lines[i]
        elif op == "double":
            lines.insert(i, lines[i])
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
    return "\n".join(lines) + "\n"


@FILES
@given(text=rig_texts())
def test_rig_files(tmp_path, text):
    p = tmp_path / "lab.toml"
    p.write_text(text, encoding="utf-8")
    check(["rig", "check", p])
    check(["where", "--offline", "--rig", p, "--db", tmp_path / "s.db"])


# -- camera calibrations (--camera-calibration) ----------------------------------------------------------------------

_JAC = {
    "format": "stickslip", "kind": "stickslip image jacobian", "version": 1, "camera": "simcam://?look=sem",
    "pixel_size_m": 5e-7, "pose": {"q1": 0.0, "q2": -1.5, "q3": 0.0, "theta": 0.0, "psi": 0.0},
    "tip_px": [100.0, 120.0], "calibration_day": "2026-11-29",
    "directions": [{"joint": j, "direction": d, "px_per_step": [0.1, -0.05], "px_per_step_sd": 0.01,
                    "residual_px": 0.2, "steps": 200, "gamma": 1e-6} for j in (1, 2, 3) for d in "+-"],
}
_JAC_VALUES = [0, -1, 1e-320, 1e308, -1e308, 2**64, 10**400, True, None, "1", [], {}, [1e308, 1e308], [0, 0],
               [float("nan"), 1], "\u202e", 0.5]


@st.composite
def jacobian_docs(draw):
    doc = json.loads(json.dumps(_JAC))
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(["top", "dir", "pose"]))
        if where == "pose" and not isinstance(doc.get("pose"), dict):
            where = "top"
        if where == "dir" and not (isinstance(doc.get("directions"), list) and len(doc["directions"]) == 6):
            where = "top"
        if where == "top":
            key = draw(st.sampled_from(sorted(doc)))
            holder = doc
        elif where == "pose":
            key, holder = draw(st.sampled_from(sorted(doc["pose"]))), doc["pose"]
        else:
            holder = doc["directions"][draw(st.integers(0, 5))]
            key = draw(st.sampled_from(sorted(holder)))
        if draw(st.booleans()):
            holder[key] = draw(st.sampled_from(_JAC_VALUES))
        else:
            holder.pop(key, None)
    return doc


def _dump(doc) -> str:
    try:
        return json.dumps(doc)
    except ValueError:  # 10**400 is written as an integer literal anyway
        return json.dumps(doc, allow_nan=True)


@pytest.fixture(scope="module")
def step_calibration(tmp_path_factory):
    """A valid step calibration, so that `move` reaches the camera calibration."""
    from test_reach import true_calibration

    p = tmp_path_factory.mktemp("cal") / "cal.json"
    true_calibration().save(p)
    return p


@FILES
@given(doc=jacobian_docs(), bom=st.sampled_from(["", "\ufeff"]))
def test_camera_calibration_files(tmp_path, step_calibration, doc, bom):
    """A valid file ends at the camera check (its camera is another URL): every refusal before it is the reader's."""
    p = tmp_path / "jac.json"
    p.write_text(bom + _dump(doc), encoding="utf-8")
    check(["move", "-d", "sim://", "-c", step_calibration, "-j", "3", "--by", "1um", "--db", tmp_path / "s.db",
           "--camera", "simcam://?look=sem&seed=3", "--camera-calibration", p])


def test_camera_calibration_loaded_is_finite():
    """Every number a loaded camera calibration gives is finite (the px per m or rad included)."""
    from stickslip.vision.jacobian import JacobianError, MeasuredJacobian

    for v in (1e308, -1e308, 1e-320):
        doc = json.loads(json.dumps(_JAC))
        doc["directions"][0]["gamma"] = v if v > 0 else 1e-6
        doc["directions"][1]["px_per_step"] = [v, v]
        try:
            jac = MeasuredJacobian.from_dict(doc)
        except JacobianError:
            continue
        for d in jac.directions:
            assert all(math.isfinite(u) for u in (*d.px_per_step, *d.px_per_unit, d.gamma, d.px_per_step_sd))


# -- vibration CSVs for tune / listen, and tables for import -----------------------------------------------------------

_CELLS = ["0.1", "-0.1", "1e308", "-1e308", "nan", "inf", "", " ", "x", "1,5", "0x1", "1e-320", "9" * 400, "１"]


@st.composite
def vibration_csvs(draw):
    head = draw(st.sampled_from(["", "# sample_rate_hz=5000\n", "# sample_rate_hz=0\n", "# sample_rate_hz=nan\n",
                                 "# sample_rate_hz=1e999\n", "# sample_rate_hz=5000\n# sample_rate_hz=8000\n",
                                 "\ufeff# sample_rate_hz=5000\n", "time_s,value\n", "value\n", "\ufefftime_s,value\n"]))
    timed = "time_s" in head or draw(st.booleans())
    n = draw(st.sampled_from([0, 1, 2, 50, 3000]))
    rate = draw(st.sampled_from([5000.0, 2000.0, 1999.0, 192000.0, 1e9]))
    rng = np.random.default_rng(draw(st.integers(0, 99)))
    rows = [f"{k / rate!r},{float(v)!r}" if timed else f"{float(v)!r}" for k, v in enumerate(rng.normal(0, 0.1, n))]
    for _ in range(draw(st.integers(0, 3))):
        if rows:
            i = draw(st.integers(0, len(rows) - 1))
            cell = draw(st.sampled_from(_CELLS))
            rows[i] = (rows[i].split(",")[0] + "," + cell) if timed and draw(st.booleans()) else cell
    if timed and rows and draw(st.booleans()):
        i = draw(st.integers(0, len(rows) - 1))
        rows[i] = rows[0]  # time going back
    eol = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    return (head + eol.join(rows) + eol).replace("\n", eol) if eol != "\n" else head + "\n".join(rows) + "\n"


@FILES
@given(text=vibration_csvs(), encoding=st.sampled_from(["utf-8", "utf-16", "latin-1"]))
def test_vibration_csvs(tmp_path, text, encoding):
    p = tmp_path / "acc.csv"
    try:
        p.write_bytes(text.encode(encoding))
    except UnicodeEncodeError:
        p.write_bytes(text.encode("utf-8"))
    check(["tune", p, "--stop-at", "0.1", "-o", tmp_path / "t.json"])
    check(["listen", p, "-t", tmp_path / "missing.json"])


_TABLE = ("day,joint,direction,q1,q2,q3,theta,psi,start,end,steps\n"
          "2026-11-20,3,+,0,-1.5,0,0,0,0,0.004,4000\n"
          "2026-11-20,3,-,0,-1.5,0,0,0,0.004,0,4100\n")


@FILES
@given(bom=st.sampled_from([b"", b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff"]), eol=st.sampled_from(["\n", "\r\n", "\r"]),
       encoding=st.sampled_from(["utf-8", "utf-16-le", "latin-1", "cp1252"]),
       huge=st.sampled_from(["", "x" * 2_000_000, "\x00", "é", '"', '"a\nb"', "\u2028"]),
       where=st.integers(0, 30))
def test_import_encodings(tmp_path, bom, eol, encoding, huge, where):
    text = _TABLE[:where] + huge + _TABLE[where:]
    p = tmp_path / "t.csv"
    try:
        p.write_bytes(bom + text.replace("\n", eol).encode(encoding))
    except UnicodeEncodeError:
        p.write_bytes(bom + text.replace("\n", eol).encode("utf-8"))
    check(["import", p, "-d", "sim://", "--db", tmp_path / "s.db"])


def test_a_camera_calibration_at_no_arms_pose_is_refused_naming_the_file(tmp_path):
    """A Pose checks itself since units58; a camera calibration file whose pose is in degrees (q2 = -90) raised the
    Pose's plain ValueError without the file's name (units58's report). Now it is the file's JacobianError."""
    from stickslip.vision.jacobian import JacobianError, MeasuredJacobian

    doc = json.loads(json.dumps(_JAC))
    doc["pose"]["q2"] = -90.0
    p = tmp_path / "cam.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(JacobianError, match=re.escape(f"{p}: pose: ")) as e:
        MeasuredJacobian.load(p)
    assert "q2" in str(e.value)
