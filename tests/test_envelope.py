"""The safety envelope (stickslip.rig.envelope) against an independent geometric check (tests/support/rig_geometry)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import rig_geometry as geo
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stickslip.kinematics import Geometry
from stickslip.rig import Arm, Box, Cylinder, EnvelopeViolation, HalfSpace, Joint, Mount, Rig, check_path, safe_fraction
from stickslip.rig.envelope import TOLERANCE, segment_distance
from stickslip.rig.model import rotation_matrix

MM3A_JOINTS = (Joint(1, 1, 1, "rotary", -2.0, 2.0), Joint(2, 2, 1, "rotary", -3.6, 0.5),
               Joint(3, 3, 1, "prismatic", 0.0, 0.012))


def mm3a(name: str = "a", origin=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), radius: float = 0.0,
         offset: float = 0.0) -> Arm:
    return Arm(name, "mm3a", "sim://", MM3A_JOINTS, Mount(origin, rotation), Geometry(offset, 0.021), radius=radius)


# ---------------------------------------------------------------- distances at one pose: analytic values


def test_segment_distances_match_closed_forms():
    box = Box("b", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    # a segment parallel to a face at height 3: distance 2; one passing a corner diagonally
    d, p = segment_distance([[-5, 0, 3]], [[5, 0, 3]], box)
    assert d == pytest.approx([2.0]) and p[0] == pytest.approx([p[0][0], 0, 3]) and abs(p[0][0]) <= 1
    d, _ = segment_distance([[3, 0, 0]], [[0, 3, 0]], box)  # the line x + y = 3 from the edge x = y = 1
    assert d == pytest.approx([1 / math.sqrt(2)])
    d, _ = segment_distance([[-5, 0.5, 0]], [[5, 0.5, 0]], box)  # through it
    assert d == pytest.approx([0.0])
    turned = Box("t", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), rotation=tuple(rotation_matrix((0, 0, math.pi / 4)).ravel()))
    d, _ = segment_distance([[3, -5, 0]], [[3, 5, 0]], turned)  # the corner at x = sqrt(2)
    assert d == pytest.approx([3 - math.sqrt(2)])
    cyl = Cylinder("c", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0, 2.0)
    d, _ = segment_distance([[-5, 3, 1]], [[5, 3, 1]], cyl)  # passes at 3 from the axis
    assert d == pytest.approx([2.0], abs=1e-8)
    d, _ = segment_distance([[0, 4, 5]], [[4, 0, 5]], cyl)  # 2 sqrt 2 - 1 sideways, 3 above
    assert d == pytest.approx([math.hypot(2 * math.sqrt(2) - 1, 3)], abs=1e-8)
    half = HalfSpace("h", (0.0, 0.0, 0.0), (0.0, 0.0, -1.0))
    d, p = segment_distance([[0, 0, 2]], [[1, 0, 5]], half)
    assert d == pytest.approx([2.0]) and p[0] == pytest.approx([0, 0, 2])


# ---------------------------------------------------------------- random rigs and paths


@st.composite
def volumes(draw):
    kind = draw(st.sampled_from(["box", "cylinder", "half-space"]))
    c = np.array([draw(st.floats(-0.04, 0.04)) for _ in range(3)])
    size = draw(st.floats(0.0005, 0.01))
    margin = draw(st.sampled_from([0.0, 1e-4, 5e-4]))
    if kind == "box":
        rot = rotation_matrix(tuple(draw(st.floats(-3.2, 3.2)) for _ in range(3)))  # type: ignore[arg-type]
        half = (size, draw(st.floats(0.0002, 0.01)), draw(st.floats(0.0002, 0.01)))
        return Box("box", tuple(c), half, margin, tuple(rot.ravel()))
    if kind == "cylinder":
        ax = np.array([draw(st.floats(-1, 1)) for _ in range(3)]) + np.array([0, 0, 1e-3])
        ax /= np.linalg.norm(ax)
        return Cylinder("cylinder", tuple(c), tuple(ax), size, draw(st.floats(0.001, 0.03)), margin)
    n = np.array([draw(st.floats(-1, 1)) for _ in range(3)]) + np.array([0, 0, 1e-3])
    n /= np.linalg.norm(n)
    return HalfSpace("half-space", tuple(c), tuple(n), margin)


def poses(draw, n):
    return np.array([[draw(st.floats(-2.0, 2.0)), draw(st.floats(-3.6, 0.5)), draw(st.floats(0.0, 0.012))]
                     for _ in range(n)])


@st.composite
def cases(draw):
    arm = mm3a(rotation=tuple(draw(st.floats(-1, 1)) for _ in range(3)), radius=draw(st.sampled_from([0.0, 3e-4])),
               offset=draw(st.sampled_from([0.0, 0.002])))
    vols = tuple(draw(st.lists(volumes(), min_size=1, max_size=2)))
    vols = tuple(dataclasses.replace(v, name=f"{v.name}{i}") for i, v in enumerate(vols))
    path = poses(draw, draw(st.integers(2, 3)))
    # small moves as often as big ones: scale the path towards its first pose
    scale = draw(st.sampled_from([1.0, 0.1, 0.01]))
    path = path[0] + scale * (path - path[0])
    return Rig("r", "r", (arm,), vols), path


def _on_path(path, q):
    """Whether pose q lies on the polyline (joint space)."""
    for a, b in zip(path[:-1], path[1:], strict=True):
        d = b - a
        t = float(np.clip(np.dot(q - a, d) / max(float(d @ d), 1e-300), 0, 1))
        if np.linalg.norm(a + t * d - q) < 1e-9:
            return True
    return False


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_accepted_paths_keep_out_and_refused_ones_come_within_the_margin(case):
    rig, path = case
    arm = rig.arms[0]
    if np.min(geo.pair_clearances(rig, arm, np.vstack((path[0], path[0])), 1)) < 1e-9:
        return  # it starts inside a margin: its way out is checked by test_a_way_out_of_a_margin_never_goes_deeper
    try:
        check_path(rig, None, path)
    except EnvelopeViolation as e:
        r = e.refusal
        q = np.array(r.q)
        assert _on_path(path, q) and 0.0 <= r.fraction <= 1.0
        if r.point is None:  # a joint limit: the independent look at the poses agrees
            assert any(not (j.lower <= p[j.number - 1] <= j.upper) for p in path for j in arm.joints)
            return
        vol = next(v for v in rig.volumes if v.name == r.obstacle)
        p = np.array(r.point)
        on_arm = min(float(geo.point_segment(p[None, :], a, b)[0]) for a, b in geo.links(arm, q))
        assert on_arm < 1e-9  # the named point is on the arm at the named pose
        allowed = arm.radius if r.start == "volume" else vol.margin + arm.radius
        assert float(geo.point_distance(p[None, :], vol)[0]) <= allowed + TOLERANCE + 1e-9
        assert r.allowed == pytest.approx(allowed)
        return
    clearance, _ = geo.dense_clearance(rig, arm, path, poses_per_segment=40, points_per_link=40)
    assert clearance >= -1e-9


@settings(max_examples=20, deadline=None)
@given(t=st.floats(0.2, 0.8), q2=st.floats(-2.8, -0.3), q3=st.floats(0.0, 0.012), thick=st.sampled_from([2e-5, 2e-4]))
def test_a_path_safe_at_both_ends_that_crosses_a_volume_between_them_is_refused(t, q2, q3, thick):
    """A thin wall across the arm's arc (at 90% of the way to the tip) between two clear ends."""
    arm = mm3a()
    a, b = np.array([-1.0, q2, q3]), np.array([1.0, q2, q3])
    mid = a + t * (b - a)
    tip = arm.tip(mid)
    # a wall through a point of the link, its thin side along the motion (the tangent of joint 1's turn)
    tangent = np.array([-math.sin(mid[0]), math.cos(mid[0]), 0.0])
    radial = np.array([math.cos(mid[0]), math.sin(mid[0]), 0.0])
    rot = np.column_stack((tangent, radial, np.cross(tangent, radial)))
    wall = Box("wall", tuple(0.9 * tip), (thick / 2, 0.0002, 0.0002), 0.0, tuple(rot.ravel()))
    rig = Rig("r", "r", (arm,), (wall,))
    for end in (a, b):  # both ends clear by the independent check
        pts = np.vstack([p0 + np.linspace(0, 1, 400)[:, None] * (p1 - p0) for p0, p1 in geo.links(arm, end)])
        assert float(np.min(geo.point_distance(pts, wall))) > 0.0
    with pytest.raises(EnvelopeViolation, match="'wall'") as e:
        check_path(rig, None, [a, b])
    assert abs(e.value.refusal.fraction - t) < 0.05


def test_the_kalman_sigma_widens_the_margin():
    arm = mm3a()
    q = np.array([0.0, -math.pi / 2, 0.0])
    tip = arm.tip(q)  # (21 mm, 0, 0)
    wall = HalfSpace("wall", tuple(tip + [0.0, 0.0, -0.0001]), (0.0, 0.0, -1.0))  # 100 µm below the tip
    rig = Rig("r", "r", (arm,), (wall,), n_sigma=3.0)
    path = [q, q + [0.1, -5e-4, 0]]  # the tip 10.5 µm lower at the end
    check_path(rig, None, path)  # no σ: clear
    # σ of 2e-3 rad on joint 2 moves the 21 mm tip by 42 µm (1σ): 3σ = 126 µm > 100 µm, and it goes deeper
    with pytest.raises(EnvelopeViolation, match=r"'wall' and the path goes deeper.*12[56]\.\d+ µm kept "
                                                r"\(12[56]\.\d+ µm of it the position's σ\)"):
        check_path(rig, None, path, q_sd=(0.0, 2e-3, 0.0))
    check_path(rig, None, path, q_sd=(0.0, 1e-3, 0.0))  # 3σ = 63 µm: clear
    # a pose refused because of its σ alone: the line says what shrinks it
    with pytest.raises(EnvelopeViolation, match=r"starts there, and 12[56]\.\d+ µm of the margin is its position's σ"):
        check_path(rig, None, path[:1], q_sd=(0.0, 2e-3, 0.0))
    with pytest.raises(EnvelopeViolation) as e:  # inside the wall itself: σ or not, no hint
        check_path(Rig("r", "r", (arm,), (dataclasses.replace(wall, point=tuple(tip + [0.0, 0.0, 1e-4])),)), None,
                   path[:1], q_sd=(0.0, 2e-3, 0.0))
    assert "σ" not in str(e.value)


def test_two_arms_keep_the_stated_distance():
    left = mm3a("left", origin=(-0.03, 0.0, 0.0), radius=5e-4)
    right = mm3a("right", origin=(0.03, 0.0, 0.0), rotation=(0.0, 0.0, math.pi), radius=5e-4)
    rig = Rig("r", "r", (left, right), (), arm_distance=1e-3)
    out = [0.0, -math.pi / 2, 0.0]  # each tip 21 mm towards the other: 18 mm apart
    # left stretches joint 3 by 12 mm: the tips come to 6 mm, then right's out by 8 mm more: 2 - 1 mm gap
    check_path(rig, "left", [out, [0.0, -math.pi / 2, 0.012]], others={"right": out})
    with pytest.raises(EnvelopeViolation, match="'arm right'") as e:
        check_path(rig, "left", [out, [0.0, -math.pi / 2, 0.012]], others={"right": [0.0, -math.pi / 2, 0.0095]})
    r = e.value.refusal
    # the allowed gap is 1 mm + two radii = 2 mm; the tips' gap closes to 18 - 12 - 9.5 = -3.5 mm: refused where
    # it first reaches 2 mm: left's q3 = 18 - 9.5 - 2 = 6.5 mm
    assert r.allowed == pytest.approx(2e-3)
    assert r.q[2] == pytest.approx(6.5e-3, abs=2e-6)


def test_joint_limits_and_soft_limits_are_part_of_the_envelope():
    joints = (MM3A_JOINTS[0], MM3A_JOINTS[1], Joint(3, 3, 1, "prismatic", 0.0, 0.012, soft_upper=0.008))
    arm = Arm("a", "mm3a", "sim://", joints, Mount(), Geometry())
    rig = Rig("r", "r", (arm,))
    with pytest.raises(EnvelopeViolation, match="joint 3 soft limit"):
        check_path(rig, None, [[0, -1, 0.0], [0, -1, 0.009]])
    with pytest.raises(EnvelopeViolation, match="joint 1 range"):
        check_path(rig, None, [[0, -1, 0.0], [2.5, -1, 0.0]])


def test_a_jog_goes_as_far_as_the_boundary():
    arm = mm3a()
    q = np.array([0.0, -math.pi / 2, 0.0])
    wall = HalfSpace("wall", (0.025, 0.0, 0.0), (1.0, 0.0, 0.0), margin=1e-4)  # x >= 25 mm, margin 0.1 mm
    rig = Rig("r", "r", (arm,), (wall,))
    frac, refusal = safe_fraction(rig, None, [q, q + [0, 0, 0.012]])  # the tip from x = 21 to 33 mm
    assert refusal is not None and refusal.obstacle == "wall"
    # it may go to x = 24.9 mm: 3.9 of 12 mm, to TOLERANCE
    assert frac * 0.012 == pytest.approx(0.0039, abs=2 * TOLERANCE)
    assert safe_fraction(rig, None, [q, q + [0, 0, 0.003]]) == (1.0, None)


def test_a_jog_stops_at_the_rig_envelope():
    """The resolved-rate jog toward a wall 50 µm beyond the tip stops within one tick's motion of its margin."""
    from stickslip.procedures.jog import JogController
    from stickslip.rig.guard import Guard
    from test_reach import CAL

    arm = mm3a()
    q = [0.0, -math.pi / 2, 0.002]
    tip = arm.tip(q)  # (23 mm, 0, 0): "d" moves the tip along +x (joint 3)
    wall = HalfSpace("wall", (float(tip[0]) + 60e-6, 0.0, 0.0), (1.0, 0.0, 0.0), margin=10e-6)
    rig = Rig("r", "r", (arm,), (wall,))
    c = JogController(CAL, list(q), speed_index=4, hold=0.0, guard=Guard(rig, "a"))  # 10 µm/s
    c.press("d", 0.0)
    t, moved = 0.0, 0
    while c.direction is not None and t < 20.0:
        steps = c.tick(t, 0.05)
        for j, n in enumerate(steps, start=1):
            if n:
                c.sent_steps(j, n)
                moved += abs(n)
        t += 0.05
    assert c.direction is None and "rig's envelope (wall)" in c.message
    gap = wall.point[0] - wall.margin - float(arm.tip(c.q)[0])
    assert 0.0 <= gap <= 10e-6 * 0.05 + 2e-6  # within one tick's motion (0.5 µm) plus a step of the arm
    assert moved > 0


def test_a_bluesky_axis_checks_the_rig_envelope(tmp_path):
    """The Bluesky axis calls the same hook: a move into a volume fails before a step is sent."""
    pytest.importorskip("ophyd_async")
    import asyncio

    from stickslip.bluesky import MoveError, StickSlipAxis
    from stickslip.rig.guard import Guard
    from stickslip.sim.arm import SimulatedMM3A
    from test_bluesky import true_calibration

    sim = SimulatedMM3A(seed=0)
    arm = mm3a()
    wall = HalfSpace("wall", (0.030, 0.0, 0.0), (1.0, 0.0, 0.0))  # x >= 30 mm: joint 3 may go to 9 mm
    rig = Rig("r", "r", (arm,), (wall,))

    async def move(target: float) -> None:
        axis = StickSlipAxis(sim, 3, true_calibration(sim), name="q3", db=tmp_path / "s.db", guard=Guard(rig, "a"))
        await axis.connect()
        await axis.set(target)

    asyncio.run(move(5e-3))
    assert sim.position(3) == pytest.approx(5e-3, abs=2e-5)  # the simulator's own step noise
    before = sim.steps_simulated
    with pytest.raises(MoveError, match="'wall'"):
        asyncio.run(move(11e-3))
    assert sim.steps_simulated == before


@pytest.mark.slow
def test_a_bluesky_manipulator_checks_the_rig_envelope_for_its_joints_and_its_tip(tmp_path):
    """StickSlipManipulator(guard=...) gives the guard to its joints and its tip: a tip move whose path enters a
    volume fails before a step is sent (before, the manipulator took no guard and the tip checked none)."""
    pytest.importorskip("ophyd_async")
    import asyncio

    from stickslip.bluesky import MoveError, StickSlipManipulator
    from stickslip.rig.guard import Guard
    from stickslip.sim.arm import SimulatedMM3A
    from test_bluesky import true_calibration

    sim = SimulatedMM3A(seed=0)
    wall = HalfSpace("wall", (0.030, 0.0, 0.0), (1.0, 0.0, 0.0))  # x >= 30 mm: the tip may go to x = 30 mm - margin
    rig = Rig("r", "r", (mm3a(),), (wall,))
    arm = StickSlipManipulator(sim, true_calibration(sim), db=tmp_path / "s.db", guard=Guard(rig, "a"))

    async def move(axis, target: float) -> None:
        await arm.connect()
        await axis.set(target)

    asyncio.run(move(arm.tip.x, 25e-3))  # outstretched along x: joint 3 out by 4 mm
    assert sim.position(3) == pytest.approx(4e-3, abs=2e-5)
    before = sim.steps_simulated
    for axis, target in ((arm.tip.x, 32e-3), (arm.q3, 11e-3)):
        with pytest.raises(MoveError, match="'wall'"):
            asyncio.run(move(axis, target))
        assert sim.steps_simulated == before


# ---------------------------------------------------------------- the σ margin grows along the path


def _track(sd: float, scale_sd: float, pose=None):
    from stickslip.motion.tracking import SCALE_CORRELATION, JointTrack

    v = scale_sd**2
    c = SCALE_CORRELATION * v
    return JointTrack(np.zeros(2), np.array([[sd**2, 0.0, 0.0], [0.0, v, c], [0.0, c, v]]), "", pose)


def _growth(tracks, steps, sigma_model):
    from stickslip.calibration.update import STEP_NOISE
    from stickslip.motion.tracking import SCALE_CORRELATION, SCALE_WALK
    from stickslip.rig.envelope import SigmaGrowth

    P = tuple(tuple(tuple(float(v) for v in row) for row in t.P) for t in tracks)
    last = tuple(None if t.pose is None else tuple(t.pose[:3]) for t in tracks)
    return SigmaGrowth(P, steps, STEP_NOISE, SCALE_WALK, sigma_model, SCALE_CORRELATION, last)


def _filtered(tracks, path, steps, sigma_model, fractions):
    """Each joint's σ at ``k + f`` for each segment k and f in ``fractions``, by the filter's own predict."""
    import copy

    from stickslip import kinematics as kin

    tracks = [copy.deepcopy(t) for t in tracks]
    out = {}
    for k in range(len(path) - 1):
        pose = kin.Pose(*path[k])
        for f in fractions:
            part = [copy.deepcopy(t) for t in tracks]
            for j in range(3):
                d = float(path[k + 1][j] - path[k][j])
                if d:
                    n = int(math.copysign(round(abs(f * d) / steps[j]), d))
                    part[j].predict(f * d, n, pose, j + 1, sigma_model[j])
            out[k + f] = [t.sd for t in part]
        for j in range(3):
            d = float(path[k + 1][j] - path[k][j])
            if d:
                tracks[j].predict(d, int(math.copysign(round(abs(d) / steps[j]), d)), pose, j + 1, sigma_model[j])
    return out


def test_the_sigma_along_a_path_is_the_kalman_filters_prediction():
    """Vertices and midpoints against JointTrack.predict run move by move (with a new pose's model error)."""
    from stickslip.rig.envelope import SigmaGrowth

    q0 = (0.0, -math.pi / 2, 0.0)
    path = np.array([q0, (0.0, -math.pi / 2, 2e-3), (0.0, -math.pi / 2 + 0.2, 2e-3), (0.0, -math.pi / 2 + 0.2, 1e-3)])
    steps, sm = (40e-6, 40e-6, 1e-6), (0.05, 0.04, 0.03)
    key3 = (0.0, round(-math.pi / 2, 9), 0.0, 0.0, 0.0)
    tracks = [_track(1e-4, 0.02), _track(2e-4, 0.03), _track(1e-6, 0.05, key3)]
    growth = _growth(tracks, steps, sm)
    expect = _filtered(tracks, path, steps, sm, (0.5, 1.0))
    s = np.array(sorted(expect))
    got = growth.sd_at(path, growth.starts(path), s)
    assert got == pytest.approx(np.array([expect[v] for v in s]), rel=1e-9)
    # joint 3 grew over its 2 mm (5 % scale σ: 50 µm half way, 100 µm at the end)
    assert got[0, 2] == pytest.approx(50e-6, rel=0.01) and got[1, 2] == pytest.approx(100e-6, rel=0.01)
    # what a jog's next tick starts from: the model at the path's end, its pose bookkeeping carried on
    after = growth.after(path)
    assert [math.sqrt(after.P[j][0][0]) for j in range(3)] == pytest.approx(expect[3.0], rel=1e-9)
    assert after.last_pose[2] == (0.0, round(-math.pi / 2 + 0.2, 9), 0.0)
    assert SigmaGrowth.constant((1e-4, 2e-4, 1e-6)).sd_at(path, SigmaGrowth.constant((1e-4, 2e-4, 1e-6)).starts(
        path), s) == pytest.approx(np.tile([1e-4, 2e-4, 1e-6], (len(s), 1)))


def test_a_path_safe_with_the_end_margin_is_refused_with_the_grown_one():
    """Joint 3 out by 4 mm towards a wall 300 µm beyond the end; σ 1 µm at the start, 5 % of the distance after."""
    arm = mm3a()
    q0 = np.array([0.0, -math.pi / 2, 0.0])  # the tip at (21 mm, 0, 0); joint 3 pushes it along +x
    path = np.array([q0, q0 + [0.0, 0.0, 4e-3]])
    wall = HalfSpace("wall", (0.021 + 0.004 + 3e-4, 0.0, 0.0), (1.0, 0.0, 0.0))
    rig = Rig("r", "r", (arm,), (wall,), n_sigma=3.0)
    tracks = [_track(0.0, 0.0), _track(0.0, 0.0), _track(1e-6, 0.05)]
    steps = (40e-6, 40e-6, 1e-6)
    check_path(rig, None, path, q_sd=(0.0, 0.0, 1e-6))  # the end margin (the start's σ): 3 µm, clear
    with pytest.raises(EnvelopeViolation, match="'wall'") as e:
        check_path(rig, None, path, q_sd=_growth(tracks, steps, (0.0, 0.0, 0.0)))
    # independently: the filter's σ and the geometry's clearance, sampled; the first sample inside the margin
    fractions = np.linspace(0.0, 1.0, 2001)[1:]
    sd = _filtered(tracks, path, steps, (0.0, 0.0, 0.0), fractions)
    first = next(f for f in fractions
                 if min(float(geo.point_distance(np.vstack([a, b]), wall).min())
                        for a, b in geo.links(arm, path[0] + f * (path[1] - path[0]))) < 3.0 * sd[f][2])
    assert first == pytest.approx(0.935, abs=0.01)  # 300 + 4000 (1 - s) = 3 x 200 s, in µm
    assert abs(e.value.refusal.fraction - first) <= 1e-3
    assert e.value.refusal.allowed == pytest.approx(3.0 * sd[first][2], rel=1e-3)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases(), st.floats(0.005, 0.1), st.floats(0.0, 2e-5))
def test_accepted_paths_keep_out_by_the_grown_margin(case, scale_sd, sd0):
    """Random rigs and paths, with σ growing by the filter: an accepted path keeps n σ of the tip from every
    volume at every sampled pose, σ from JointTrack.predict and the tip's σ from the Jacobian (kinematics)."""
    from stickslip import kinematics as kin

    rig, path = case
    arm = rig.arms[0]
    tracks = [_track(sd0, scale_sd), _track(sd0, scale_sd), _track(sd0 * 1e-3, scale_sd)]
    steps = (40e-6, 40e-6, 1e-6)
    try:
        check_path(rig, None, path, q_sd=_growth(tracks, steps, (0.0, 0.0, 0.0)))
    except EnvelopeViolation as e:  # the named point is within the margin grown to where it is on the path
        r = e.refusal
        if r.point is None or r.start == "volume":
            return  # a limit, or a collision already at the start (test_a_way_out_of_a_margin_never_goes_deeper)
        at = r.fraction * (len(path) - 1)
        k = min(int(at), len(path) - 2)
        joint_sd = _filtered(tracks, path[:k + 2], steps, (0.0, 0.0, 0.0), (at - k,))[k + (at - k)]
        margin = rig.n_sigma * float(np.linalg.norm(kin.tip_sd(np.array(r.q), joint_sd, arm.geometry)))
        vol = next(v for v in rig.volumes if v.name == r.obstacle)
        allowed = vol.margin + arm.radius + margin
        assert r.allowed == pytest.approx(allowed, rel=1e-6, abs=1e-12)
        assert float(geo.point_distance(np.array(r.point)[None, :], vol)[0]) <= allowed + TOLERANCE + 1e-9
        return
    start_sd = np.array([sd0, sd0, sd0 * 1e-3])
    start = rig.n_sigma * float(np.linalg.norm(kin.tip_sd(path[0], start_sd, arm.geometry)))
    if np.min(geo.pair_clearances(rig, arm, np.vstack((path[0], path[0])), 1)) < start + 1e-9:
        return  # it starts inside a margin: test_a_way_out_of_a_margin_never_goes_deeper
    fractions = np.linspace(0.0, 1.0, 21)[1:]
    sd = _filtered(tracks, path, steps, (0.0, 0.0, 0.0), fractions)
    u = np.linspace(0.0, 1.0, 40)[:, None]
    for s, joint_sd in sd.items():
        k = min(int(s), len(path) - 2) if s < len(path) - 1 else len(path) - 2
        t = s - k
        q = path[k] + t * (path[k + 1] - path[k])
        margin = rig.n_sigma * float(np.linalg.norm(kin.tip_sd(q, joint_sd, arm.geometry)))
        pts = np.vstack([a + u * (b - a) for a, b in geo.links(arm, q)])
        for v in rig.volumes:
            assert float(np.min(geo.point_distance(pts, v))) >= v.margin + arm.radius + margin - 1e-9


def test_a_new_pose_adds_the_models_error_once_along_a_path():
    """Joint 3, joint 2, joint 3, joint 2, joint 3: the filter move by move would add σ_model² to joint 3's scales
    at each of its moves after the first; along one path (a reach's segments, a jog session) it is added once."""
    q = [0.0, -math.pi / 2, 0.0]
    path = [list(q)]
    for j, d in ((3, 1e-3), (2, 0.1), (3, 1e-3), (2, 0.1), (3, 1e-3)):
        q[j - 1] += d
        path.append(list(q))
    path = np.array(path)
    steps = (40e-6, 40e-6, 1e-6)
    key3 = (0.0, round(-math.pi / 2, 9), 0.0, 0.0, 0.0)
    tracks = [_track(0.0, 0.0), _track(0.0, 0.0), _track(1e-6, 0.02, key3)]
    growth = _growth(tracks, steps, (0.0, 0.0, 0.05))
    got = growth.sd_at(path, growth.starts(path), np.array([5.0]))[0, 2]
    once = _filtered(tracks[:2] + [_track(1e-6, 0.02, key3)], path[:4], steps, (0.0, 0.0, 0.05), (1.0,))[3.0][2]
    assert growth.after(path[:4]).bumped == (False, False, True)
    # the filter's prediction over the first three moves (one pose change), then the last with no new error
    t = _track(1e-6, 0.02, key3)
    from stickslip import kinematics as kin

    for k in range(4):
        d = float(path[k + 1][2] - path[k][2])
        if d:
            t.predict(d, round(d / 1e-6), kin.Pose(*path[k]), 3, 0.05)
    assert t.sd == pytest.approx(once, rel=1e-9)
    t.predict(1e-3, 1000, None, 3, 0.0)  # no pose: no new model error
    assert got == pytest.approx(t.sd, rel=1e-9)


# ---------------------------------------------------------------- starting inside a margin


def _wall_in_reach(margin: float, below: float):
    """An arm whose tip (21 mm, 0, 0) is ``below`` m above a 10 mm wide block's top (the arm's base 16 mm away)."""
    arm = mm3a()
    q = np.array([0.0, -math.pi / 2, 0.0])
    wall = Box("wall", (0.021, 0.0, -below - 1e-3), (5e-3, 5e-3, 1e-3), margin=margin)
    return Rig("r", "r", (arm,), (wall,)), q


def test_a_way_out_of_a_margin_is_accepted_and_a_way_deeper_refused():
    rig, q = _wall_in_reach(margin=1e-4, below=4e-5)  # 40 µm above the wall, 60 µm inside its margin
    up = q + [0.0, 0.01, 0.0]  # joint 2 turns the 21 mm tip up by 210 µm: out, then clear
    check_path(rig, None, [q, up])
    check_path(rig, None, [q, q + [0.3, 0.0, 0.0]])  # joint 1 turns it about z: no lower anywhere
    with pytest.raises(EnvelopeViolation) as e:  # down: deeper
        check_path(rig, None, [q, q - [0.0, 0.001, 0.0]])
    r = e.value.refusal
    assert r.start == "margin" and r.obstacle == "wall" and r.fraction < 0.01
    assert r.distance == pytest.approx(4e-5, abs=1e-7) and r.allowed == pytest.approx(1e-4)
    assert "move away from 'wall', or observe or reference its joints to shrink σ" in str(e.value)
    # out, then down again into the margin: the normal rule once out
    with pytest.raises(EnvelopeViolation) as e:
        check_path(rig, None, [q, up, up - [0.0, 0.0095, 0.0]])
    assert e.value.refusal.start == "" and e.value.refusal.fraction > 0.5
    # a jog: all the way up, not a step down
    assert safe_fraction(rig, None, [q, up]) == (1.0, None)
    assert safe_fraction(rig, None, [q, q - [0.0, 0.001, 0.0]])[0] == 0.0
    # a pose alone (rig check) is still reported inside the margin
    with pytest.raises(EnvelopeViolation, match="closer than the 100.00 µm allowed"):
        check_path(rig, None, [q])


def test_a_start_inside_a_volume_is_refused_whichever_way_it_goes():
    rig, q = _wall_in_reach(margin=1e-4, below=-2e-5)  # the tip 20 µm inside the wall
    for path in ([q, q + [0.0, 0.01, 0.0]], [q, q + [0.3, 0.0, 0.0]]):
        with pytest.raises(EnvelopeViolation, match="inside 'wall' already") as e:
            check_path(rig, None, path)
        assert e.value.refusal.start == "volume" and e.value.refusal.fraction == 0.0


def test_the_sigma_margin_counts_on_the_way_out():
    """In the margin by its σ alone: out while the distance gains on the σ, not along the wall."""
    rig, q = _wall_in_reach(margin=0.0, below=1e-4)
    rig = dataclasses.replace(rig, n_sigma=3.0)
    sd = (0.0, 2e-3, 0.0)  # 3σ of the 21 mm tip: 126 µm > 100 µm
    check_path(rig, None, [q, q + [0.0, 0.01, 0.0]], q_sd=sd)
    with pytest.raises(EnvelopeViolation, match="observe or reference its joints to shrink σ"):
        check_path(rig, None, [q, q - [0.0, 0.001, 0.0]], q_sd=sd)


@st.composite
def starts_in_a_margin(draw):
    rig, path = draw(cases())
    path = path[0] + draw(st.sampled_from([0.1, 0.01])) * (path - path[0])
    arm, i = rig.arms[0], draw(st.integers(0, len(rig.volumes) - 1))
    v = rig.volumes[i]
    d0 = min(geo.link_distance(a, b, v) for a, b in geo.links(arm, path[0]))
    margin = max(d0 - arm.radius, 0.0) + draw(st.floats(1e-6, 3e-4))
    vols = tuple(dataclasses.replace(w, margin=margin) if j == i else w for j, w in enumerate(rig.volumes))
    return dataclasses.replace(rig, volumes=vols), path


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(starts_in_a_margin())
@pytest.mark.slow
def test_a_way_out_of_a_margin_never_goes_deeper(case):
    """Accepted from inside a margin: no (link, volume) pair's clearance falls while inside, none enters."""
    rig, path = case
    arm = rig.arms[0]
    try:
        check_path(rig, None, path)
    except EnvelopeViolation as e:
        r = e.refusal
        q = np.array(r.q)
        assert _on_path(path, q)
        if r.point is None:
            return
        vol = next(v for v in rig.volumes if v.name == r.obstacle)
        d = min(geo.link_distance(a, b, vol) for a, b in geo.links(arm, q))
        if r.start == "volume":  # a collision already where it starts
            assert r.fraction == 0.0 and d <= arm.radius + 1e-9
        else:  # where it is refused it is within the margin (deeper, or back in)
            assert d - vol.margin - arm.radius <= TOLERANCE + 1e-9
        return
    c = geo.pair_clearances(rig, arm, path, 30)  # (poses, links, volumes), m
    before = np.maximum.accumulate(c, axis=0)[:-1]
    floor = np.where(c[0] < 0, np.minimum(before, 0.0), 0.0) - TOLERANCE - 1e-8
    assert np.all(c[1:] >= floor)


def test_a_volume_kept_no_distance_from_is_still_kept_out_of():
    """No margin, links of no radius, no σ (a rig file's defaults at `rig check`): inside a volume was a clearance
    of 0, not below 0, and a pose inside it, or a link through it, was reported as no problem."""
    box = Box("holder", (0.005, 0.0, 0.0), (0.002, 0.002, 0.002))  # across the link from the base to the 21 mm tip
    rig = Rig("r", "r", (mm3a(),), (box,), n_sigma=0.0)
    q = np.array([0.0, -math.pi / 2, 0.0])
    with pytest.raises(EnvelopeViolation, match="the path enters 'holder'") as e:
        check_path(rig, None, [q])
    assert e.value.refusal.distance == 0.0 and e.value.refusal.allowed == 0.0
    for path in ([q, q + [0.0, 0.01, 0.0]], [q, q + [0.0, 0.0, 0.001]]):  # any move from there: a collision already
        with pytest.raises(EnvelopeViolation, match="inside 'holder' already") as e:
            check_path(rig, None, path)
        assert e.value.refusal.start == "volume"
    assert safe_fraction(rig, None, [q, q + [0.0, 0.01, 0.0]])[0] == 0.0
    away = q + [1.0, 0.0, 0.0]  # turned 57 deg about z: 2.4 mm clear of the box
    check_path(rig, None, [away])
    with pytest.raises(EnvelopeViolation, match="the path enters 'holder'|reaches the edge"):
        check_path(rig, None, [away, q])  # turning back into it


def test_two_arms_kept_no_distance_apart_still_may_not_overlap():
    """Links of no radius, arms kept 0 apart: two arms facing each other along one line overlap by 12 mm, and
    their links were 1e-18 m apart by rounding, so a clearance of 1e-18 m let it pass."""
    a = mm3a("a", origin=(-0.015, 0.0, 0.0))
    b = mm3a("b", origin=(0.015, 0.0, 0.0), rotation=(0.0, 0.0, math.pi))
    rig = Rig("r", "r", (a, b), ())
    q = np.array([0.0, -math.pi / 2, 0.0])
    with pytest.raises(EnvelopeViolation, match="the path enters 'arm b'"):
        check_path(rig, "a", [q], others={"b": q})
    check_path(rig, "a", [q + [1.0, 0.0, 0.0]], others={"b": q})  # a turned 57 deg about z: 5 mm clear of b
