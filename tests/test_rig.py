"""The rig file (stickslip.rig): read, checked on load, one-line errors naming file, line and key."""

from __future__ import annotations

import math
import sys
import types

import numpy as np
import pytest

from stickslip import kinematics as kin
from stickslip.joints import JOINTS, MM3A_FILE
from stickslip.rig import PasswordMissing, RigError, controller_url, load_rig, mm3a_rig, parse_rig
from stickslip.rig.load import line_of

GOOD = """\
name = "bench"
arm_distance = "1mm"
n_sigma = 2

[stage]
tilt = "10deg"

[[arm]]
name = "left"
controller = "mm3a+socket://127.0.0.1:4001"
calibration = "cal/left.json"
mount = { origin = ["-30mm", "0mm", "0mm"], rotation = ["0deg", "0deg", "0deg"] }

[[arm]]
name = "right"
kind = "xyz"
controller = "smaract-mcs2://127.0.0.1:4002"
password_env = "RIG_TEST_PASSWORD"
tool = ["0mm", "0mm", "-10mm"]

  [[arm.joint]]
  channel = 2
  range = ["-10mm", "10mm"]

  [[arm.joint]]
  channel = 1
  sign = -1
  range = ["-10mm", "10mm"]

  [[arm.joint]]
  channel = 3
  range = ["-10mm", "10mm"]
  soft = ["-5mm", "5mm"]
  stops = ["lower"]

[[volume]]
name = "objective"
shape = "cylinder"
base = ["0mm", "0mm", "5mm"]
axis = [0, 0, 1]
radius = "5mm"
height = "20mm"
margin = "200um"

[[volume]]
name = "sample"
shape = "half-space"
point = ["0mm", "0mm", "-25mm"]
normal = [0, 0, -1]
on_stage = true

[[volume]]
name = "holder"
shape = "box"
lower = ["-1mm", "-2mm", "-3mm"]
upper = ["1mm", "2mm", "3mm"]

[[position]]
name = "park"
arm = "left"
q2 = "-90deg"
q3 = "0mm"
order = [3, 2]
"""


def test_a_good_file_reads_into_numbers_in_si(tmp_path):
    p = tmp_path / "rig.toml"
    p.write_text(GOOD, encoding="utf-8")
    rig = load_rig(p)
    assert [a.name for a in rig.arms] == ["left", "right"] and rig.arm().name == "left"
    assert rig.arm_distance == pytest.approx(1e-3) and rig.n_sigma == 2.0
    left, right = rig.arms
    assert left.joints == mm3a_rig().arms[0].joints  # an mm3a arm takes the shipped joints
    assert left.geometry == kin.DEFAULT_GEOMETRY and left.mount.origin == pytest.approx((-0.03, 0, 0))
    assert [j.channel for j in right.joints] == [2, 1, 3] and right.joints[1].sign == -1
    assert right.joints[2].limits == pytest.approx((-5e-3, 5e-3)) and right.joints[2].stops == ("lower",)
    cyl, half, box = rig.volumes
    assert cyl.radius == pytest.approx(5e-3) and cyl.margin == pytest.approx(2e-4)
    # the stage tilt turns the on-stage half-space about x by 10 deg: its normal (0,0,-1) -> (0, sin, -cos)
    assert half.normal == pytest.approx((0.0, math.sin(math.radians(10)), -math.cos(math.radians(10))))
    assert box.half == pytest.approx((1e-3, 2e-3, 3e-3))
    park = rig.position("left", "park")
    assert park.q == (None, pytest.approx(-math.pi / 2), 0.0) and park.order == (3, 2)


def test_the_shipped_mm3a_file_is_what_the_code_assumes():
    """joints.JOINTS and kinematics.DEFAULT_GEOMETRY come from the file: the paper's numbers exactly."""
    arm = mm3a_rig().arms[0]
    assert MM3A_FILE.is_file()
    assert JOINTS[2].lower == -7 * math.pi / 6 and JOINTS[2].upper == math.pi / 6
    assert JOINTS[1].span == 4 * math.pi / 3 and JOINTS[3].upper == 0.012
    assert kin.DEFAULT_GEOMETRY.length == 0.021 and kin.DEFAULT_GEOMETRY.offset == 0.0
    for j in arm.joints:
        assert (j.lower, j.upper) == pytest.approx((JOINTS[j.number].lower, JOINTS[j.number].upper), abs=1e-15)
    # its tip is the kinematics' tip
    for q in ([0.1, -1.2, 0.003], [-0.5, -2.5, 0.011]):
        assert arm.tip(q) == pytest.approx(kin.tip(q), abs=1e-15)


BAD = [
    # (old text, new text, the text on the line the error must name (first such line), words in the message)
    ('name = "bench"', 'name = "bench', 'name = "bench', "not TOML"),
    ("n_sigma = 2", 'n_sigma = 2\ncolour = "red"', "colour", "colour: unknown key"),
    ('tilt = "10deg"', 'tilt = "10mm"', "tilt", "stage.tilt: unknown angle unit"),
    ('tilt = "10deg"', "tilt = true", "tilt", "must be an angle such as"),
    ('tilt = "10deg"', 'tilt = "100deg"', "tilt", "within ±90 deg"),
    ('4001"', '4001?password=hunter2"', "4001", "no password"),
    ('"mm3a+socket://127.0.0.1:4001"', '"mm3a+socket://u:hunter2@h:4001"', "4001", "no password"),
    ('name = "right"', 'name = "left"', 'kind = "xyz"', "a second arm named"),  # the second arm's name line
    ('kind = "xyz"', 'kind = "scara"', "scara", "no arm kind"),
    ("channel = 3", "channel = 2", "channel = 2", "two joints on one channel"),
    ("sign = -1", "sign = 2", "sign = 2", "must be 1 or -1"),
    ('soft = ["-5mm", "5mm"]', 'soft = ["-5mm", "15mm"]', "soft", "within the range"),
    ('range = ["-10mm", "10mm"]\n  soft', 'range = ["10mm", "-10mm"]\n  soft', '["10mm", "-10mm"]',
     "less than upper"),
    ('stops = ["lower"]', 'stops = ["top"]', "stops", "end stops"),
    ('shape = "cylinder"', 'shape = "sphere"', "sphere", "no shape"),
    ('radius = "5mm"', 'radius = "-5mm"', 'radius = "-5mm"', "greater than 0"),
    ("axis = [0, 0, 1]", "axis = [0, 0, 0]", "axis", "zero vector"),
    ('height = "20mm"', 'height = "20km"', "height", "unknown length unit"),
    ('height = "20mm"', 'height = "20"', "height", "more than 10 m"),
    ('upper = ["1mm", "2mm", "3mm"]', 'upper = ["1mm", "-3mm", "3mm"]', "upper", "exceed lower"),
    ('margin = "200um"', "margin = 200", "margin", "more than 10 m"),
    ('arm = "left"\nq2', 'arm = "middle"\nq2', "middle", "no arm named 'middle'"),
    ('q2 = "-90deg"', 'q2 = "-300deg"', "q2", "outside joint 2's limits"),
    ("order = [3, 2]", "order = [3, 1]", "order", "each joint the position gives"),
    ("order = [3, 2]", 'order = [3, "2"]', "order", "each joint the position gives"),  # sorted() raised TypeError
    ("order = [3, 2]", "order = [[3], 2]", "order", "each joint the position gives"),
    ('password_env = "RIG_TEST_PASSWORD"', 'password_env = "not a name"', "password_env", "environment variable"),
    ('tool = ["0mm", "0mm", "-10mm"]', 'tool = ["0mm", "-10mm"]', "tool", "array of 3"),
    ('tilt = "10deg"', 'tilt = "10deg"\n[[volume]]\nname = "far"\nshape = "box"\nlower = [0, 0, 0]\n'
     'upper = ["1mm", "1mm", "1mm"]\nrotation = ["0deg", "0deg", "1e300deg"]', "1e300deg",
     "more than ten turns"),  # found by tests/test_fuzz_files.py: its sine is noise, the box turned any way
]


def _line(text: str, marker: str, nth: int = 1) -> int:
    found = [n for n, line in enumerate(text.splitlines(), start=1) if marker in line]
    return found[nth - 1]


@pytest.mark.parametrize("old,new,marker,words", BAD, ids=[b[3] for b in BAD])
def test_each_kind_of_error_is_one_line_naming_file_line_and_key(tmp_path, old, new, marker, words):
    p = tmp_path / "rig.toml"
    text = GOOD.replace(old, new, 1)
    assert text != GOOD
    line = _line(text, marker) - (1 if marker == 'kind = "xyz"' else 0)
    if marker == "channel = 2":
        line = _line(text, marker, 2)  # the second joint on channel 2
    p.write_text(text, encoding="utf-8")
    with pytest.raises(RigError) as e:
        load_rig(p)
    msg = str(e.value)
    assert "\n" not in msg and "hunter2" not in msg and "Traceback" not in msg
    assert msg.startswith(f"{p}:{line}:"), msg
    assert words in msg


def test_missing_arms_and_files_are_one_line_errors(tmp_path):
    with pytest.raises(RigError, match=r"rig.toml: arm: a rig needs at least one \[\[arm\]\]"):
        parse_rig('name = "x"\n', "rig.toml")
    with pytest.raises(RigError, match="no-such.toml"):
        load_rig(tmp_path / "no-such.toml")
    with pytest.raises(RigError, match=r"arm\[1\]: an xyz arm needs its 3"):
        parse_rig('[[arm]]\nname = "a"\nkind = "xyz"\ncontroller = "sim://"\n', "r.toml")


def test_line_of_counts_arrays_of_tables():
    text = GOOD
    assert line_of(text, ("arm", 1, "joint", 2, "soft")) == _line(text, "soft")
    assert line_of(text, ("arm", 1, "joint", 0)) == _line(text, "[[arm.joint]]")
    assert line_of(text, ("arm", 1, "joint", 1, "range")) == _line(text, "range", 2)
    assert line_of(text, ("volume", 2, "upper")) == _line(text, "upper")
    assert line_of(text, ("arm", 0, "mount", "origin")) == _line(text, "mount")  # in an inline table: its line


def test_the_password_comes_from_the_environment_or_the_keyring(monkeypatch):
    rig = parse_rig(GOOD, "rig.toml")
    right = rig.arm("right")
    monkeypatch.delenv("RIG_TEST_PASSWORD", raising=False)
    with pytest.raises(PasswordMissing, match=r"\$RIG_TEST_PASSWORD is not set"):
        controller_url(right)
    monkeypatch.setenv("RIG_TEST_PASSWORD", "s3cr&t")
    assert controller_url(right) == "smaract-mcs2://127.0.0.1:4002?password=s3cr%26t"
    assert controller_url(rig.arm("left")) == "mm3a+socket://127.0.0.1:4001"  # no source: the URL as written
    kr = parse_rig(GOOD.replace('password_env = "RIG_TEST_PASSWORD"',
                                'password_keyring = { service = "stickslip", user = "right" }'), "r.toml").arm("right")
    monkeypatch.setitem(sys.modules, "keyring", None)  # not installed
    with pytest.raises(PasswordMissing, match="pip install keyring"):
        controller_url(kr)
    fake = types.ModuleType("keyring")
    fake.get_password = lambda service, user: {("stickslip", "right"): "k3y"}.get((service, user))  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "keyring", fake)
    assert controller_url(kr).endswith("?password=k3y")


def test_links_in_the_rig_frame_follow_the_mount():
    rig = parse_rig(GOOD.replace('rotation = ["0deg", "0deg", "0deg"]', 'rotation = ["0deg", "0deg", "90deg"]'), "r")
    left = rig.arm("left")
    q = np.array([0.0, -math.pi / 2, 0.002])
    # the tip at (23 mm, 0, 0) in the base frame, turned 90 deg about z, then moved by the origin
    assert left.tip(q) == pytest.approx((-0.03, 0.023, 0.0), abs=1e-12)
    right = rig.arm("right")
    assert right.tip([0.001, 0.002, 0.003]) == pytest.approx((0.001, 0.002, 0.003 - 0.01))


def test_a_direction_of_huge_or_tiny_components_is_a_unit_vector():
    """Found by tests/test_fuzz_files.py: the norm of [1e308, 1e308, 0] overflowed and the axis became (0, 0, 0)."""
    for axis, want in (("[1e308, 0, 1e308]", (math.sqrt(0.5), 0.0, math.sqrt(0.5))), ("[0, 0, 1e-320]", (0, 0, 1))):
        rig = parse_rig(GOOD.replace("axis = [0, 0, 1]", f"axis = {axis}", 1), "rig.toml")
        got = next(v for v in rig.volumes if v.shape == "cylinder").axis
        assert got == pytest.approx(want, abs=1e-12)


TWO_ARMS = '[[arm]]\nname = "a"\ncontroller = "{a}"\n\n[[arm]]\nname = "b"\ncontroller = "{b}"\n'


@pytest.mark.parametrize("a, b", [
    ("sim://", "sim://?seed=0"),  # one simulated arm (its device key): both arms were driving its channels 1-3
    ("sim://", "sim://?timeout=5"),
    ("mm3a://COM3", "mm3a://com3"),  # Windows' port names have no case
    ("mm3a:///COM3", "mm3a://COM3?timeout=5"),  # one port, as serial_port_name opens it
    ("mm3a:///dev/ttyS_REAL", "mm3a:///dev/ttyS_LINK"),  # a link to the device file (by-id) is the device
])
def test_one_controller_spelled_two_ways_is_one_controller(tmp_path, a, b):
    real = tmp_path / "ttyS_REAL"
    real.touch()
    try:
        (tmp_path / "ttyS_LINK").symlink_to(real)
    except OSError:  # Windows without the right to make links
        if "ttyS" in a:
            pytest.skip("no symlinks here")
    a, b = (u.replace("/dev/", f"{tmp_path.as_posix()}/") for u in (a, b))
    with pytest.raises(RigError, match=r"^p.toml:7: arm\[2\]\.controller: arm 'a' drives channel 1 of this controller"):
        parse_rig(TWO_ARMS.format(a=a, b=b), "p.toml")


@pytest.mark.parametrize("a, b", [
    ("sim://", "sim://?seed=2"), ("mm3a://COM3", "mm3a://COM4"),
    ("mm3a://COM3?channels=ABC", "mm3a://com3?channels=DEF"),  # a channel map each: taken as theirs (docs/rig.md)
])
def test_two_controllers_or_two_channel_maps_are_two(a, b):
    assert [x.name for x in parse_rig(TWO_ARMS.format(a=a, b=b), "p.toml").arms] == ["a", "b"]


def test_two_names_differing_only_in_case_are_refused():
    """'Probe' and 'probe' are one name to whoever types --arm or a position's arm: refused, naming both."""
    two = TWO_ARMS.format(a="sim://", b="sim://?seed=2").replace('"b"', '"A"')
    with pytest.raises(RigError, match=r"^p.toml:6: arm\[2\]\.name: a second arm named 'A' \('a' differs only in case"):
        parse_rig(two, "p.toml")
    vols = "".join(f'\n[[volume]]\nname = "{n}"\nshape = "half-space"\npoint = [0, 0, -0.01]\nnormal = [0, 0, -1]\n'
                   for n in ("Sample", "sample"))
    with pytest.raises(RigError, match=r"^p.toml:16: volume\[2\]\.name: a second volume named 'sample'"):
        parse_rig(TWO_ARMS.format(a="sim://", b="sim://?seed=2") + vols, "p.toml")


@pytest.mark.parametrize("value, shown", [("30", "30 rad (1719 deg)"), ('"-90"', "-90 rad (-5157 deg)"),
                                          ("1e2", "100.0 rad (5730 deg)")])
def test_a_bare_angle_of_more_than_a_turn_is_refused_as_degrees_without_their_unit(value, shown):
    """A bare number is radians (docs/rig.md); the base turned by 30 rad where 30 deg was meant was accepted
    (a mount 1719 deg about z: the arm drawn and checked 72 deg from where it stands)."""
    text = TWO_ARMS.format(a="sim://", b="sim://?seed=2") + f"mount = {{ rotation = [0, 0, {value}] }}\n"
    with pytest.raises(RigError, match=r"^p.toml:8: arm\[2\]\.mount\.rotation: .* has no unit, so it is "
                       + shown.replace("(", r"\(").replace(")", r"\)") + ": more than a turn; write its unit"):
        parse_rig(text, "p.toml")
    ok = parse_rig(TWO_ARMS.format(a="sim://", b="sim://?seed=2") + "mount = { rotation = [0, 0, 3.1] }\n", "p.toml")
    assert ok.arms[1].mount.rotation == (0.0, 0.0, 3.1)  # a bare angle within a turn is radians, as documented


def test_the_drawing_names_a_half_space_where_its_edge_enters_the_view_not_on_another_volume():
    """The docs' rig (an objective over the origin, a tilted sample plane through it): the top view wrote
    "sample" on top of "objective" (both at the origin); the line's end would put it on the arm "probe"."""
    pytest.importorskip("matplotlib")
    from stickslip.rig.draw import figure

    rig = parse_rig(
        'name = "t"\n[stage]\ntilt = "52deg"\n'
        '[[arm]]\nname = "probe"\nkind = "mm3a"\ncontroller = "sim://"\nmount = { origin = ["-30mm", "0mm", "0mm"] }\n'
        '[[volume]]\nname = "objective"\nshape = "cylinder"\nbase = ["0mm", "0mm", "4mm"]\naxis = [0, 0, 1]\n'
        'radius = "8mm"\nheight = "40mm"\n'
        '[[volume]]\nname = "sample"\nshape = "half-space"\npoint = ["0mm", "0mm", "-0.5mm"]\nnormal = [0, 0, -1]\n'
        "on_stage = true\n"
    )
    fig = figure(rig, {a.name: a.home for a in rig.arms})
    try:
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        for ax in fig.axes:
            boxes = {t.get_text(): t.get_window_extent(renderer) for t in ax.texts}
            assert not any(boxes["sample"].overlaps(b) for t, b in boxes.items() if t != "sample"), ax.get_title()
            assert ax.bbox.contains(*boxes["sample"].p0)  # inside its panel
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
