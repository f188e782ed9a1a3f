"""A move of one arm while another arm of the rig moves or is uncertain (rig52).

Before rig52 any path was refused while another arm was in flight, claimed or uncertain
(``ArmUnknown``, audit46 design question 2): one arm of a rig moved at a time, even 60 mm
apart. Now the path keeps the rig's ``arm_distance`` from every pose the other arm may take:
each joint anywhere over its claimed or uncertain range, the others at their kept values.
The boundary is checked against the independent geometry of ``rig_geometry`` (points along
the links, the other arm's sweep sampled densely), not against the envelope's own code.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from rig_geometry import links, point_segment
from server_support import RIG

from stickslip.devices.positions import load_state, save_state
from stickslip.procedures.arms import guard_for
from stickslip.procedures.move import MoveRefused
from stickslip.rig import Rig, load_rig
from stickslip.rig.guard import ArmUnknown, Guard
from stickslip.storage import Store
from test_rig_race import arm_move

H = -math.pi / 2  # joint 2 outstretched: the probe's tip at (-9, 0, 0) mm, the other's at (+9, 0, 0) mm (q3 = 0)


@pytest.fixture()
def rig(tmp_path: Path) -> Rig:
    path = tmp_path / "rig.toml"
    path.write_text(RIG.replace("{lid}", "30mm"), encoding="utf-8")
    return load_rig(path)


def other_in_flight(store: Store, rig: Rig, to: float) -> None:
    """The other arm's move of joint 3 from 0 to ``to`` (m) claimed, its first burst in flight (as kept mid-move)."""
    key, specs = rig.state_key("other"), rig.arm("other").joint_specs()
    s = load_state(store, key, specs)
    s.claim_path([[0.0, H, 0.0], [0.0, H, to]])
    s.intend(3, to / 4)
    save_state(store, s)


def test_an_arm_clear_of_the_others_sweep_moves_while_it_is_in_flight(rig: Rig, tmp_path: Path) -> None:
    # the other arm (mounted 60 mm away) claims joint 3 from 0 to 1 mm: its tip sweeps (+9..+8, 0, 0) mm; the
    # probe's 1 mm move takes its tip from -9 to -8 mm, 16 mm clear. Before rig52: refused ("may be anywhere")
    store = Store.open(tmp_path / "rig.db")
    other_in_flight(store, rig, 1e-3)
    r = arm_move(store, rig, "probe", by=1e-3)
    assert r.outcome.error is None and r.outcome.sent > 0
    kept = load_state(store, rig.state_key("probe"), rig.arm("probe").joint_specs())
    assert kept.positions[3] == pytest.approx(1e-3, abs=1e-6) and not kept.claim and not kept.uncertain
    other = load_state(store, rig.state_key("other"), rig.arm("other").joint_specs())
    assert other.claim == {3: (0.0, 1e-3)} and other.uncertain == {3: (0.0, 2.5e-4)}  # untouched


def test_a_path_into_the_others_sweep_is_refused(rig: Rig, tmp_path: Path) -> None:
    # the other arm claims joint 3 from 0 to 9 mm: its tip sweeps to (0, 0, 0). The probe's 8.5 mm move ends
    # 0.5 mm from it (1 mm kept): refused, naming the arm and what to do; nothing moved, nothing claimed
    store = Store.open(tmp_path / "rig.db")
    other_in_flight(store, rig, 9e-3)
    with pytest.raises(MoveRefused) as e:
        arm_move(store, rig, "probe", by=8.5e-3)
    line = str(e.value)
    assert "\n" not in line and "arm 'probe': arm 'other' may be anywhere along a move" in line, line
    assert "a move of it claims its joint 3 between 0 µm and 9000 µm" in line
    assert "'arm other'" in line and "wait for its move to end" in line
    kept = load_state(store, rig.state_key("probe"), rig.arm("probe").joint_specs())
    assert kept.positions[3] == 0.0 and not kept.claim and not kept.uncertain


def swing_guard(rig: Rig, swept: bool = True) -> Guard:
    """The probe's guard while the other arm (q3 = 8 mm: its tip at +1 mm) swings joint 2 by ±0.5 rad about
    outstretched (kept at one end): its tip sweeps an arc through (+1, 0, 0) mm; at either end it is 3.5 mm
    back and 13.9 mm up or down. ``swept=False``: the kept end pose only (as a still arm)."""
    kept = [0.0, H - 0.5, 8e-3]
    box = [(0.0, 0.0), (H - 0.5, H + 0.5), (8e-3, 8e-3)]
    if not swept:
        return Guard(rig, "probe", {"other": kept})
    return Guard(rig, "probe", {"other": kept}, {"other": "a move of it claims its joint 2"}, swept={"other": box})


def probe_path(e: float) -> list[list[float]]:
    return [[0.0, H, 0.0], [0.0, H, e]]


def test_the_sweep_between_the_ends_is_kept_from(rig: Rig) -> None:
    # the probe's tip to (+0.5, 0, 0) mm: 0.5 mm from the arc's middle, 14 mm from the other arm at either end
    swing_guard(rig, swept=False).check(probe_path(9.5e-3))  # clear of the kept end pose
    Guard(rig, "probe", {"other": [0.0, H + 0.5, 8e-3]}).check(probe_path(9.5e-3))  # and of the other end
    swing_guard(rig).check(probe_path(7.9e-3))  # its tip 2.1 mm from the arc's middle: clear
    with pytest.raises(ArmUnknown) as e:
        swing_guard(rig).check(probe_path(9.5e-3))
    line = str(e.value)
    assert line.startswith("arm 'probe': arm 'other' may be anywhere along a move (a move of it claims its joint 2)")
    # named: a pose of the path just past its first problem (joint 3 at 9 mm: the tip 1 mm from the arc's middle,
    # +1 mm), and its distance from a pose the other arm may take (closer than allowed: so refused)
    m = re.search(r"the path comes ([0-9.]+) µm from 'arm other', closer than the 1000.00 µm allowed at .* "
                  r"(9[0-9])% along the path, q = \(0.000 deg, -90.000 deg, ([0-9.]+) µm\)", line)
    assert m is not None, line
    assert float(m[1]) < 1000.0 and 9000.0 <= float(m[3]) <= 9100.0, line


def independent_boundary(rig: Rig) -> float:
    """The probe's joint 3 extent (m) at which it first comes within 1 mm of the other arm's swing: the links at
    60 points each, the swing at 1001 poses, the probe's joint 3 every 0.5 µm over 8.99..9.01 mm."""
    u = np.linspace(0.0, 1.0, 60)[:, None]
    q3s = np.arange(8.99e-3, 9.01e-3, 0.5e-6)
    pts = np.vstack([a + u * (b - a) for q3 in q3s for a, b in links(rig.arm("probe"), np.array([0.0, H, q3]))])
    least = np.full(len(q3s), np.inf)
    for q2 in np.linspace(H - 0.5, H + 0.5, 1001):
        for a, b in links(rig.arm("other"), np.array([0.0, q2, 8e-3])):
            least = np.minimum(least, point_segment(pts, a, b).reshape(len(q3s), -1).min(axis=1))
    below = np.flatnonzero(least < 1e-3)
    assert len(below), "the sampled range never comes within 1 mm"
    return float(q3s[below[0]])


def test_the_boundary_matches_an_independent_geometry(rig: Rig) -> None:
    # analytically the probe's tip meets the arc's middle (+1 mm) 1 mm away at joint 3 = 9 mm exactly
    e = independent_boundary(rig)
    assert abs(e - 9e-3) <= 1e-6, e
    swing_guard(rig).check(probe_path(e - 2e-6))
    with pytest.raises(ArmUnknown):
        swing_guard(rig).check(probe_path(e + 2e-6))


def test_an_arm_uncertain_over_its_whole_range_is_kept_from_over_all_of_it(rig: Rig, tmp_path: Path) -> None:
    # the other arm's joint 3 uncertain from 0 to its upper limit (12 mm: its tip anywhere from +9 to -3 mm):
    # the probe's 1 mm move (tip to -8 mm) goes, its 6 mm move (tip to -3 mm) is refused
    store = Store.open(tmp_path / "rig.db")
    key, specs = rig.state_key("other"), rig.arm("other").joint_specs()
    s = load_state(store, key, specs)
    s.mark_uncertain(3, *rig.arm("other").joint(3).limits, "a move was interrupted")
    save_state(store, s)
    guard = guard_for(store, rig, "probe")
    assert guard.swept["other"] == [(0.0, 0.0), (H, H), (0.0, 12e-3)]
    guard.check(probe_path(1e-3))
    with pytest.raises(ArmUnknown, match="its joint 3 is in flight or uncertain, between 0 µm and 12000 µm"):
        guard.check(probe_path(6e-3))


def random_rig(x_mm: float, other: tuple[float, float], turn_deg: float) -> str:
    """A rig of audit55's random rigs: the probe at -x on the x axis, the other arm at (x, y, z) mm turned about z."""
    y, z = other
    return f"""\
name = "r"
arm_distance = "1mm"

[[arm]]
name = "probe"
controller = "sim://"
mount = {{ origin = ["{-x_mm}mm", "0mm", "0mm"] }}

[[arm]]
name = "other"
controller = "sim://?seed=2"
mount = {{ origin = ["{x_mm}mm", "{y}mm", "{z}mm"], rotation = ["0deg", "0deg", "{turn_deg}deg"] }}
"""


def test_a_start_inside_only_a_coarse_boxs_pad_is_not_walked_out_of(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    # found by random rigs (audit55): the probe's start lies inside the bound of the other arm's whole box (its pad:
    # joint 2 over 2.2 rad) but not near any pose of it; before, the way out of a margin was walked over the whole
    # path, poses 1 µm of motion apart, against the coarse box (62 s for this one check). Now the box is cut at the
    # start first, and the check never takes the way out
    from stickslip.rig import envelope

    path = tmp_path / "rig.toml"
    path.write_text(random_rig(10.3071, (-2.1870, -1.6154), 125.9830), encoding="utf-8")
    rig = load_rig(path)
    box = [(1.3295152590627084, 2.0824456174366186), (-1.9204776002791681, 0.2585119277109649),
           (0.0024164342941520238, 0.010522427319877868)]
    kept = [1.927679389899452, -0.7310659063602332, 0.005633775366887818]
    moves = [[1.8496594652608866, -2.381042675652152, 0.004744633098323784],
             [0.042903659609476286, 0.03689313221213775, 0.008786679333831995]]
    start = np.vstack([np.asarray(a) + np.linspace(0, 1, 60)[:, None] * (np.asarray(b) - np.asarray(a))
                       for a, b in links(rig.arm("probe"), np.asarray(moves[0]))])
    least = min(float(point_segment(start, a, b).min()) for q in np.stack(np.meshgrid(
        *[np.linspace(lo, hi, 9) for lo, hi in box]), -1).reshape(-1, 3) for a, b in links(rig.arm("other"), q))
    assert least > 1.5e-3  # the start is clear of every sampled pose of the box, by more than arm_distance

    def no_way_out(*args: object, **kwargs: object) -> object:
        raise AssertionError("walked the way out of a margin")

    monkeypatch.setattr(envelope, "_escape", no_way_out)
    Guard(rig, "probe", {"other": kept}, {"other": "a move of it claims its joint 2"}, swept={"other": box}).check(
        moves)


def test_a_start_within_the_distance_kept_from_a_sweep_is_refused_without_a_way_out(tmp_path: Path,
                                                                                     monkeypatch) -> None:
    """audit55's random rig (seed 1, trial 31): the probe's start passes within 1 mm of a pose of the other arm's box
    (joint 1 swinging 143 deg), and the way out of a margin, walked against the boxes poses 0.1 µm of motion apart,
    took over 400 s before refusing. It is refused at once, never walked."""
    import stickslip.rig.envelope as envelope

    (tmp_path / "rig.toml").write_text(random_rig(13.2834, (0.2994, -0.5514), 215.8084), encoding="utf-8")
    rig = load_rig(tmp_path / "rig.toml")
    path = [[-0.5372037365931377, -3.1750929677074735, 0.006293982864365944],
            [1.2530166523874318, 0.0675538233783235, 0.011737334252404964]]
    box = [(-1.1833832609204327, 1.3157765946823776), (-1.515346985787787, -1.515346985787787),
           (0.00355924080839708, 0.005708316649029406)]
    # the independent geometry: the start is within the 1 mm kept from a pose of the box
    start = [a + u * (b - a) for a, b in links(rig.arm("probe"), np.asarray(path[0]))
             for u in np.linspace(0.0, 1.0, 200)]
    least = min(float(point_segment(np.asarray(start), a, b).min())
                for q1 in np.linspace(*box[0], 181) for q3 in np.linspace(*box[2], 5)
                for a, b in links(rig.arm("other"), np.asarray([q1, box[1][0], q3])))
    assert 0.9e-3 < least < rig.arm_distance

    def no_walk(*_a: object, **_k: object) -> None:
        raise AssertionError("the way out of a margin was walked against a swept box")

    monkeypatch.setattr(envelope, "_escape", no_walk)
    guard = Guard(rig, "probe", {"other": [0.05928, box[1][0], 0.0048046]}, {"other": "a move"},
                  swept={"other": box})
    with pytest.raises(ArmUnknown) as refused:
        guard.check(path)
    assert refused.value.refusal.start == "sweep" and refused.value.refusal.fraction == 0.0
    text = str(refused.value)
    assert "starts within the distance kept from the poses 'arm other' may take" in text
    assert "wait for its move to end" in text and text.count("\n") == 0
